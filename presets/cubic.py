"""Regular simple-cubic lattice: one ball per cell and the three axis beams."""


def lattice(n: Range(1, 200) = 10, cell: Range(0.1, 10) = 1.0, radius: Range(0.01, 0.45) = 0.1):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius * cell)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(n, Translation(Vec(0, 0, cell)))
    return lat
