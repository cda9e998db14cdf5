"""Thesis Fig. 6.3: a scaled, rotated and swirled lattice made entirely by GUI edits."""


def lattice(thickness: Range(0.02, 0.12) = 0.0645):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), thickness)
    for di, dj, dk in [(1, 0, 0), (0, 1, 0), (0, 1, 1), (1, 1, 0)]:
        lat.add_beam(a, a, di, dj, dk)
    lat.set_u(7, Scaling(1.187, Pt(-3.333, 0, 0)))
    lat.set_v(12, Rotation(0.285, Vec(0, 0, 1), Pt(-1.555, 0.003, 0)))
    lat.set_w(15, Swirl(0.224, Vec(0, 1, 0), Pt(10.872, 0, 0.039), 0.953))
    return lat
