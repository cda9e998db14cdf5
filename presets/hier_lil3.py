"""Three-level Lattice-in-Lattice (thesis Fig. 9.3): fine cubic, medium BCC frame, coarse ring of thick balls."""

import math


def lattice(n: Range(8, 160) = 40, fine_radius: Range(0.02, 0.2) = 0.08, medium_radius: Range(0.2, 2.0) = 0.7,
            coarse_radius: Range(1.0, 12.0) = 7.0):
    fine = Lattice()
    a = fine.add_node(Pt(0, 0, 0), fine_radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        fine.add_beam(a, a, *off)
    fine.set_u(n, Translation(Vec(1, 0, 0)))
    fine.set_v(n, Translation(Vec(0, 1, 0)))
    fine.set_w(n, Translation(Vec(0, 0, 1)))
    # medium: a body-centred frame with cells of 8 fine cells
    cell = 8.0
    cells = math.ceil((n - 1) / cell) + 1
    medium = Lattice()
    c = medium.add_node(Pt(0, 0, 0), medium_radius, "corner")
    m = medium.add_node(Pt(cell / 2, cell / 2, cell / 2), medium_radius, "centre")
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        medium.add_beam(c, c, *off)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                medium.add_beam(m, c, di, dj, dk)
    medium.set_u(cells, Translation(Vec(cell, 0, 0)))
    medium.set_v(cells, Translation(Vec(0, cell, 0)))
    medium.set_w(cells, Translation(Vec(0, 0, cell)))
    # coarse: a ring of thick balls around the block's vertical axis keeps only a tube of the medium
    half = (n - 1) / 2
    coarse = Lattice()
    b = coarse.add_node(Pt(half + half * 0.55, half, 0), coarse_radius)
    coarse.add_beam(b, b, 1, 0, 0)
    coarse.add_beam(b, b, 0, 1, 0)
    coarse.set_u(12, Rotation(2 * math.pi / 12, Vec(0, 0, 1), Pt(half, half, 0)))
    coarse.set_v(3, Translation(Vec(0, 0, (n - 1) / 2)))
    fine.set_filter(LiL(FilteredLattice(medium, LiL(coarse))))
    return fine
