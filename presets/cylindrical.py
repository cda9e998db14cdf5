"""Cylindrical steady lattice: radial U, angular V (rotation about z), axial W; 2 balls, 14 beam-patterns."""

import math


def lattice(nu: Range(1, 64) = 8, nv: Range(3, 256) = 32, nw: Range(1, 256) = 16,
            inner: Range(0.5, 20) = 4.0, radius: Range(0.01, 0.3) = 0.08):
    lat = Lattice()
    angle = 2 * math.pi / nv
    step = inner * angle  # cells roughly square at the inner radius
    c = lat.add_node(Pt(inner, 0, 0), radius * step, "corner")
    m = lat.add_node(Pt(inner + step / 2, 0, step / 2), radius * step, "centre")
    # the centre ball sits half a step around the axis: rotate it into place
    lat.nodes[m].center = Rotation(angle / 2, Vec(0, 0, 1), Pt(0, 0, 0)).apply_points(lat.nodes[m].center)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(c, c, *off)
    lat.add_beam(m, m, 1, 0, 0)
    lat.add_beam(m, m, 0, 1, 0)
    lat.add_beam(m, m, 0, 0, 1)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                lat.add_beam(m, c, di, dj, dk)
    lat.set_u(nu, Translation(Vec(step, 0, 0)))
    lat.set_v(nv, Rotation(angle, Vec(0, 0, 1), Pt(0, 0, 0)))
    lat.set_w(nw, Translation(Vec(0, 0, step)))
    return lat
