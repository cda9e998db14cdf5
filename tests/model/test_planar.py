"""Five-point planar steady 2-maps (§2.6.5), planar shapes rolled onto cones (§4.3.2) and
seamless self-overlap by corner snapping (§4.4.3), against complex arithmetic, arc lengths and
coinciding grid vertices."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from ple import BeCOTSField, Lattice, Pt
from ple.errors import PleError
from ple.model.planar import ShapeOntoCone, SteadyMap2, snap_corner

FIVE = [Pt(0, 0, 0), Pt(4, 0.5, 0), Pt(-0.5, 3, 0), Pt(3.2, 4.1, 0), Pt(2.1, -0.6, 0)]


def test_five_point_map_interpolates_and_is_steady():
    m = SteadyMap2.from_five(*FIVE)
    got = m(np.array([0, 1, 0, 1, 0.5]), np.array([0, 0, 1, 1, 0]))
    assert np.allclose(got, FIVE, atol=1e-12)
    # V from complex arithmetic: z -> C + (D - C)/(B - A) (z - A); M(u, v + 1) = V(M(u, v))
    a, b, c, d = (complex(p[0], p[1]) for p in FIVE[:4])
    q = (d - c) / (b - a)
    uv = np.random.default_rng(0).uniform(0, 1, (20, 2))
    p0, p1 = m(uv[:, 0], uv[:, 1]), m(uv[:, 0], uv[:, 1] + 1)
    z0 = p0[:, 0] + 1j * p0[:, 1]
    zv = c + q * (z0 - a)
    assert np.allclose(p1[:, 0] + 1j * p1[:, 1], zv, atol=1e-9)
    cell = Lattice()
    n = cell.add_node(FIVE[0], 0.1)
    cell.add_beam(n, n, 1, 0, 0)
    lat = m.lattice(cell, (4, 3))
    c_, _ = lat.node_balls(np.array([[4, 0, 0, 0], [0, 3, 0, 0], [4, 3, 0, 0], [2, 0, 0, 0]]))
    assert np.allclose(c_, [FIVE[1], FIVE[2], FIVE[3], FIVE[4]], atol=1e-9)
    with pytest.raises(PleError, match="one plane"):
        SteadyMap2.from_five(Pt(0, 0, 0), Pt(1, 0, 0), Pt(0, 1, 0), Pt(1, 1, 0.5), Pt(0.5, 0, 0))


CORNERS = (Pt(0, 0, 0), Pt(0, 2, 0.3), Pt(2.5, 2.2, 1.0), Pt(2, 0, 0.2))


def test_shape_onto_cone_is_an_isometry_onto_the_cone():
    roll = ShapeOntoCone(*CORNERS)
    pre = roll.preimages()
    assert np.allclose(roll(pre), np.array(CORNERS), atol=1e-12)  # corners come back
    # a straight segment in the plane keeps its length on the cone (polyline arc length)
    t = np.linspace(0, 1, 4001)[:, None]
    seg = pre[0] + t * (pre[2] - pre[0]) + np.array([0.3, -0.2]) * np.sin(math.pi * t)
    flat_len = np.linalg.norm(np.diff(seg, axis=0), axis=1).sum()
    bent = roll(seg)
    assert np.linalg.norm(np.diff(bent, axis=0), axis=1).sum() == pytest.approx(flat_len, rel=1e-6)
    # every image lies on the cone: the angle between FP and the axis is the cone's β
    f, axis = roll.cone.apex, roll.cone.axis
    fp = bent - f
    ang = np.arccos(np.clip(fp @ axis / np.linalg.norm(fp, axis=1), -1, 1))
    assert np.allclose(ang, roll.cone.beta, atol=1e-9)
    with pytest.raises(PleError, match="non-coplanar"):
        ShapeOntoCone(Pt(0, 0, 0), Pt(0, 2, 0), Pt(2.5, 2.2, 0), Pt(2, 0, 0))


def test_snapped_corner_makes_a_seamless_tiling():
    base = BeCOTSField.from_corners(Pt(1, 0, 0), Pt(0.2, 1.1, 0), Pt(-1.3, 0.2, 0), Pt(0.9, -0.3, 0))
    fld = replace(base, u=(0.02, 8.9), v=(0.04, 0.9))  # U wraps well over a full turn
    counts, vertex = (4, 6), (1, 3)
    snapped = snap_corner(fld, counts, vertex)
    nu, nv = counts
    a, b = np.meshgrid(np.arange(0, nu - 2), np.arange(3, nv + 1), indexing="ij")
    a, b = a.reshape(-1), b.reshape(-1)
    p = snapped.points(a / nu, b / nv)
    q = snapped.points((a + nu - vertex[0]) / nu, (b - vertex[1]) / nv)
    assert np.allclose(p, q, atol=1e-9)
    assert np.allclose(snapped.points([1.0], [0.0]), snapped.points([vertex[0] / nu], [vertex[1] / nv]))
    assert np.allclose(snapped.a, fld.a) and snapped.v == fld.v
    # the unsnapped field is not seamless
    assert not np.allclose(fld.points(a / nu, b / nv), fld.points((a + nu - 1) / nu, (b - 3) / nv), atol=1e-3)
    with pytest.raises(PleError, match="0 turns"):
        snap_corner(replace(base, u=(0.02, 0.3), v=(0.04, 0.2)), counts, vertex)
