"""Rectified steady warps (thesis §3.1–3.4, §3.8): rectified nodes against independent
rectification of the warped regular lattice, steadiness of node-groups and beams, edge cases."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ple import Lattice, Pt, Rotation, Scaling, Screw, Swirl, Translation, Vec
from ple.errors import PleError
from ple.measure.integrals import lattice_measures
from ple.meshing.tessellate import tessellate
from ple.model.warp import TETRAHEDRON, RectifiedWarp, circumsphere
from ple.program.sources import load_lattice
from ple.queries import biq


def _cell() -> Lattice:
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0.3), 0.15)
    b = cell.add_node(Pt(0.5, 0.5, 0.0), 0.1)
    cell.add_beam(a, a, 1, 0, 0)
    cell.add_beam(a, a, 0, 1, 0)
    cell.add_beam(a, b)
    cell.add_beam(b, a, 1, 1, 0)
    return cell


def _sphere_lstsq(points):
    """Sphere through points by linear least squares |p|^2 = 2 c.p + (r^2 - |c|^2) (independent)."""
    p = np.asarray(points)
    a = np.concatenate([2 * p, np.ones((len(p), 1))], axis=1)
    sol = np.linalg.lstsq(a, (p**2).sum(1), rcond=None)[0]
    c = sol[:3]
    return c, np.sqrt(sol[3] + c @ c)


def _warp_reference(u, v, w, origin, cell_pts, counts, slab):
    """M(u, v, w) from 4x4 matrices of the similarities' powers, one point at a time."""
    out = []
    for x, y, z in cell_pts:
        pu, pv = x / counts[0], y / counts[1]
        m = v.power_matrices([pv])[0] @ u.power_matrices([pu])[0]
        if slab:
            o = np.append(np.asarray(origin) + [0, 0, z], 1)
        else:
            m = w.power_matrices([z / counts[2]])[0] @ m
            o = np.append(origin, 1)
        out.append((m @ o)[:3])
    return np.array(out)


def test_circumsphere_and_coplanar_points():
    rng = np.random.default_rng(0)
    c, r = rng.normal(size=3), 1.7
    pts = c + r * TETRAHEDRON @ np.linalg.qr(rng.normal(size=(3, 3)))[0]
    cc, rr = circumsphere(pts)
    assert np.allclose(cc, c) and np.isclose(rr, r)
    with pytest.raises(PleError, match="coplanar"):
        circumsphere([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])


def test_slab_rows_along_v_are_rectified_warped_nodes():
    u = Swirl(0.9, Vec(0, 0, 1), Pt(0, -7, 0), 0.7)
    v = Screw(0.5, Vec(0, 1, 0), Pt(0, 0, 0), 6)
    counts = (8, 6, 1)
    warp = RectifiedWarp(u, v, None, Pt(0.2, 0.1, 0), counts)
    lat = warp.lattice(_cell())
    for j in range(counts[1]):
        for n, node in enumerate(_cell().nodes):
            pts = _warp_reference(u, v, None, np.array([0.2, 0.1, 0]), node.center + [0, j, 0] + node.radius
                                  * TETRAHEDRON, counts, True)
            c, r = _sphere_lstsq(pts)
            got_c, got_r = lat.node_balls(np.array([[0, j, 0, n]]))
            assert np.allclose(got_c[0], c, atol=1e-9) and abs(got_r[0] - r) < 1e-9


def test_commuting_warp_rectifies_every_node_and_groups_are_similar():
    # U and V share an axis and fixed point: they commute, so every rectified node is the
    # rectification of its own warped pre-image (§3.3)
    u = Rotation(1.1, Vec(0, 0, 1), Pt(0, -5, 0))
    v = Scaling(1.6, Pt(0, -5, 0))
    counts = (7, 5, 1)
    warp = RectifiedWarp(u, v, None, Pt(0, 0, 0), counts)
    lat = warp.lattice(_cell())
    ev = lat.evaluate()
    for row, (i, j, _, n) in enumerate(ev.node_index):
        node = _cell().nodes[n]
        pts = _warp_reference(u, v, None, np.zeros(3), node.center + [i, j, 0] + node.radius * TETRAHEDRON,
                              counts, True)
        c, r = _sphere_lstsq(pts)
        assert np.allclose(ev.center[row], c, atol=1e-9) and abs(ev.radius[row] - r) < 1e-9
    # node-groups are similar: within a group, distances and radii scale by one factor
    c0, r0 = lat.node_balls(np.array([[0, 0, 0, 0], [0, 0, 0, 1]]))
    for i, j in ((3, 2), (6, 4)):
        c1, r1 = lat.node_balls(np.array([[i, j, 0, 0], [i, j, 0, 1]]))
        f = r1[0] / r0[0]
        assert abs(r1[1] / r0[1] - f) < 1e-9
        assert abs(np.linalg.norm(c1[0] - c1[1]) / np.linalg.norm(c0[0] - c0[1]) - f) < 1e-9


def test_brick_rows_along_w_and_steadiness_of_beams():
    u = Swirl(0.6, Vec(0, 0, 1), Pt(0, -9, 0), 0.8)
    v = Translation(Vec(0, 4, 0))
    w = Scaling(0.7, Pt(2, 2, 12))
    counts = (4, 4, 5)
    warp = RectifiedWarp(u, v, w, Pt(0, 0, 0), counts)
    cell = _cell()
    cell.add_beam(0, 0, 0, 0, 1)
    lat = warp.lattice(cell)
    for k in range(counts[2]):
        node = cell.nodes[0]
        pts = _warp_reference(u, v, w, np.zeros(3), node.center + [0, 0, k] + node.radius * TETRAHEDRON, counts,
                              False)
        c, r = _sphere_lstsq(pts)
        got_c, got_r = lat.node_balls(np.array([[0, 0, k, 0]]))
        assert np.allclose(got_c[0], c, atol=1e-9) and abs(got_r[0] - r) < 1e-9
    # steady beams: consecutive beams along W have lengths in the ratio of W's step factor
    ev = lat.evaluate()
    step = (w ** (1 / counts[2])).factor
    a = ev.beam_nodes[(ev.beam_index[:, 3] == len(cell.beams) - 1) & (ev.beam_index[:, 0] == 1)
                      & (ev.beam_index[:, 1] == 2)]
    lengths = np.linalg.norm(ev.center[a[:, 0]] - ev.center[a[:, 1]], axis=1)
    assert np.allclose(lengths[1:] / lengths[:-1], step, atol=1e-9)


def test_edge_beams_removed_and_measures_closed_form_match_sum():
    """§3.8: beams leaving the lattice are not made; the closed-form measures count only present ones."""
    lat = load_lattice(str(Path(__file__).parents[2] / "presets" / "rectified_warp.py"), {"nu": 4, "nv": 3})
    ev = lat.evaluate()
    assert len(ev.beam_nodes) == lat.beam_count() == 3 * 3 + 4 * 2 + 4 * 3 + 3 * 3 + 4 * 2 + 3 * 2
    closed = lattice_measures(lat)
    total = lattice_measures(lat, method="sum")
    assert closed["volume"] == pytest.approx(total["volume"], rel=1e-9)
    assert tessellate(lat, style="refined", levels=2).is_watertight
    # the measure against Monte Carlo point membership (RangeFinder PMC on the steady rows)
    lo, hi = lat.bounds()
    pts = np.random.default_rng(5).uniform(lo, hi, (200000, 3))
    frac = biq.pmc(lat, pts).mean()
    box = np.prod(hi - lo)
    assert abs(frac * box - closed["volume"]) < 4 * box * np.sqrt(frac * (1 - frac) / len(pts))


def test_bad_counts_named():
    with pytest.raises(PleError, match="one layer"):
        RectifiedWarp(Rotation(1, Vec(0, 0, 1), Pt(0, 0, 0)), Translation(Vec(0, 1, 0)), None, Pt(0, 0, 0), (2, 2, 3))
