"""LiL coarse (thesis Fig. 7.9): cylindrical 5×17×9 around thesis_cylindrical, ring closed, 1 ball, 3 beam-patterns."""

import math


def lattice(nu: Range(2, 20) = 5, nv: Range(3, 64) = 17, nw: Range(2, 64) = 9, inner: Range(0.5, 50) = 20.0,
            outer: Range(1, 200) = 50.4, height: Range(1, 500) = 124.7, radius: Range(0.1, 10) = 1.5):
    lat = Lattice()
    a = lat.add_node(Pt(inner, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(nu, Translation(Vec((outer - inner) / (nu - 1), 0, 0)))
    # nv groups around the ring, the last one on the first: the ring closes
    lat.set_v(nv, Rotation(2 * math.pi / (nv - 1), Vec(0, 0, 1), Pt(0, 0, 0)))
    lat.set_w(nw, Translation(Vec(0, 0, height / (nw - 1))))
    return lat
