"""Gyroid-filtered octet-like cubic lattice: fine nodes kept inside the network of a gyroid (graded cells)."""


def lattice(n: Range(4, 80) = 30, radius: Range(0.02, 0.3) = 0.1, cell: Range(2.0, 40.0) = 15.0,
            level: Range(-1.0, 1.0) = -0.5, sheet: bool = False):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, 1, 1), (1, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    field = TPMSField("gyroid", cell)
    lat.set_filter(ImplicitFilter(field, level if not sheet else abs(level) + 0.3, "sheet" if sheet else "network"))
    return lat
