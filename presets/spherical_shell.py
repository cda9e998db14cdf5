"""Spherical shell: meridian and azimuth rotations on a sphere, radial layers by a swirl (graded, twisted)."""

import math


def lattice(nu: Range(2, 64) = 10, nv: Range(3, 128) = 24, nw: Range(1, 16) = 3, sphere: Range(1, 50) = 5.0,
            radius: Range(0.01, 0.3) = 0.08, grading: Range(1.0, 1.6) = 1.2, twist: Range(0.0, 0.5) = 0.1):
    lat = Lattice()
    polar0 = 0.35  # stay away from the poles, where a meridian grid pinches
    step = (math.pi - 2 * polar0) / (nu - 1)
    start = Rotation(polar0, Vec(1, 0, 0), Pt(0, 0, 0)).apply_points(Pt(0, 0, sphere))
    a = lat.add_node(start, radius * sphere * step)
    lat.add_beam(a, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 0, -(nv - 1), 0)  # closes each azimuth ring: last group back to the first
    lat.add_beam(a, a, 0, 0, 1)
    lat.add_beam(a, a, 1, 1, 1)
    lat.set_u(nu, Rotation(step, Vec(1, 0, 0), Pt(0, 0, 0)))
    lat.set_v(nv, Rotation(2 * math.pi / nv, Vec(0, 0, 1), Pt(0, 0, 0)))
    lat.set_w(nw, Swirl(twist, Vec(0, 0, 1), Pt(0, 0, 0), grading))
    return lat
