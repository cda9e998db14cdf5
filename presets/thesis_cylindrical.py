"""Thesis cylindrical lattice (§7.4, Table 7.2): 32×128×128 groups (radial U, angular V, axial W), 2 balls, 14 beams."""

import math


def lattice(nu: Range(1, 64) = 32, nv: Range(3, 512) = 128, nw: Range(1, 512) = 128,
            inner: Range(0.5, 50) = 20.0, radius: Range(0.01, 0.2) = 0.06):
    lat = Lattice()
    angle = 2 * math.pi / nv
    step = inner * angle  # cells roughly cubic at the inner radius
    c = lat.add_node(Pt(inner, 0, 0), radius * step, "corner")
    # the centre ball: half a step out, up, and around the axis
    centre = Rotation(angle / 2, Vec(0, 0, 1), Pt(0, 0, 0)).apply_points(Pt(inner + step / 2, 0, step / 2))
    m = lat.add_node(centre, radius * step, "centre")
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(c, c, *off)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(m, m, *off)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                lat.add_beam(m, c, di, dj, dk)
    lat.set_u(nu, Translation(Vec(step, 0, 0)))
    lat.set_v(nv, Rotation(angle, Vec(0, 0, 1), Pt(0, 0, 0)))
    lat.set_w(nw, Translation(Vec(0, 0, step)))
    return lat
