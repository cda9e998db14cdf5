"""LiL coarse (thesis Fig. 7.9): regular n³ cubic frame over the 75³ thesis_regular box, 1 ball, 3 beam-patterns."""


def lattice(n: Range(2, 50) = 9, span: Range(1, 500) = 74.0, radius: Range(0.01, 0.45) = 0.12):
    lat = Lattice()
    cell = span / (n - 1)
    a = lat.add_node(Pt(0, 0, 0), radius * cell)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(n, Translation(Vec(0, 0, cell)))
    return lat
