"""Kagome-like slab: trihexagonal (corner-sharing triangles) single-layer lattice in the xy plane."""


def lattice(nu: Range(1, 200) = 12, nv: Range(1, 200) = 12, cell: Range(0.1, 10) = 1.0,
            radius: Range(0.01, 0.2) = 0.05):
    lat = Lattice()
    h = cell / 2
    s3 = 3 ** 0.5
    a = lat.add_node(Pt(0, 0, 0), radius * cell, "a")
    b = lat.add_node(Pt(h, 0, 0), radius * cell, "b")
    c = lat.add_node(Pt(h / 2, h * s3 / 2, 0), radius * cell, "c")
    lat.add_beam(a, b)
    lat.add_beam(b, c)
    lat.add_beam(c, a)
    lat.add_beam(b, a, 1, 0, 0)
    lat.add_beam(c, a, 0, 1, 0)
    lat.add_beam(b, c, 1, -1, 0)
    lat.set_u(nu, Translation(Vec(cell, 0, 0)))
    lat.set_v(nv, Translation(Vec(h, h * s3, 0)))
    return lat
