"""Thesis regular lattice (§7.4, Table 7.2): 75³ cubic cells, corner + body-centre balls, 14 beam-patterns."""


def lattice(n: Range(1, 200) = 75, cell: Range(0.1, 10) = 1.0, radius: Range(0.01, 0.2) = 0.06):
    lat = Lattice()
    c = lat.add_node(Pt(0, 0, 0), radius * cell, "corner")
    m = lat.add_node(Pt(cell / 2, cell / 2, cell / 2), radius * cell, "centre")
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:  # 3 cube edges
        lat.add_beam(c, c, *off)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:  # 3 centre-centre struts
        lat.add_beam(m, m, *off)
    for di in (0, 1):  # 8 centre-corner struts
        for dj in (0, 1):
            for dk in (0, 1):
                lat.add_beam(m, c, di, dj, dk)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(n, Translation(Vec(0, 0, cell)))
    return lat
