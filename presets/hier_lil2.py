"""Two-level Lattice-in-Lattice: a fine BCC lattice kept only where it meets a coarse cubic frame."""


def lattice(n: Range(4, 60) = 24, coarse_cells: Range(1, 8) = 3, fine_radius: Range(0.02, 0.2) = 0.06,
            coarse_radius: Range(0.2, 2.0) = 0.9):
    fine = Lattice()
    c = fine.add_node(Pt(0, 0, 0), fine_radius, "corner")
    m = fine.add_node(Pt(0.5, 0.5, 0.5), fine_radius, "centre")
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        fine.add_beam(c, c, *off)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                fine.add_beam(m, c, di, dj, dk)
    fine.set_u(n, Translation(Vec(1, 0, 0)))
    fine.set_v(n, Translation(Vec(0, 1, 0)))
    fine.set_w(n, Translation(Vec(0, 0, 1)))
    # the coarse lattice: a cubic frame whose beams are thick enough to hold fine cells
    step = (n - 1) / coarse_cells
    coarse = Lattice()
    a = coarse.add_node(Pt(0, 0, 0), coarse_radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        coarse.add_beam(a, a, *off)
    coarse.set_u(coarse_cells + 1, Translation(Vec(step, 0, 0)))
    coarse.set_v(coarse_cells + 1, Translation(Vec(0, step, 0)))
    coarse.set_w(coarse_cells + 1, Translation(Vec(0, 0, step)))
    fine.set_filter(LiL(coarse))
    return fine
