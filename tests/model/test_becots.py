"""BeCOTS fields, maps, inversion, patterns, lattices, stacks and connectors (thesis §4, §6.3),
checked against independent truth: corner positions, matrix products, brute-force sums,
Umeyama/Kabsch fits and the naive BIQ."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from ple.algebra.similarity import Rotation, Screw, Translation
from ple.errors import PleError
from ple.io.irfile import save_ir
from ple.meshing.connectors import constant_radius_connectors, kabsch
from ple.model.becots import BeCOTSField, becots_of
from ple.model.becots_builders import becots_lattice, set_field, stack_lattice
from ple.model.ir import lattice_from_dict, lattice_to_dict
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice
from ple.queries import biq
from ple.queries.becots_rangefinder import stack_pmc
from scipy.spatial import cKDTree

CORNERS = [[0, 0, 0], [0, 3, 0.5], [3.5, 3.2, 1.5], [3, 0, 0.2]]
coord = st.floats(-3, 3, allow_nan=False, allow_infinity=False)
point = st.tuples(coord, coord, coord)


def _field_or_skip(pts, branch=(0, 0)) -> BeCOTSField:
    pts = np.array(pts, float)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    assume(d[np.triu_indices(4, 1)].min() > 0.3)
    try:
        return BeCOTSField.from_corners(*pts, branch=branch)
    except PleError:
        assume(False)


def umeyama_residual(p: np.ndarray, q: np.ndarray) -> float:
    """Max distance after the best similarity p -> q (independent least-squares fit)."""
    pc, qc = p - p.mean(0), q - q.mean(0)
    u, s, vt = np.linalg.svd(pc.T @ qc)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1, 1, d]) @ u.T
    scale = (s * [1, 1, d]).sum() / (pc ** 2).sum()
    return float(np.linalg.norm(scale * pc @ rot.T - qc, axis=1).max())


# ----- fields from corners ------------------------------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(st.tuples(point, point, point, point))
def test_field_reproduces_corners_and_commutes(pts):
    f = _field_or_skip(pts)
    scale = max(1.0, float(np.abs(pts).max()))
    assert np.abs(f.corners - np.array(pts)).max() <= 1e-9 * scale
    uv, vu = (f.U @ f.V).matrix, (f.V @ f.U).matrix
    assert np.abs(uv - vu).max() <= 1e-9 * max(1.0, np.abs(uv).max())
    # U takes A to D and V takes A to B as plain matrices (SPEC §5)
    a = np.append(pts[0], 1.0)
    assert np.allclose((f.U.matrix @ a)[:3], pts[3], atol=1e-9 * scale)
    assert np.allclose((f.V.matrix @ a)[:3], pts[1], atol=1e-9 * scale)


def test_map_is_the_field_applied_to_a():
    f = BeCOTSField.from_corners(*CORNERS)
    x, y = np.random.default_rng(0).uniform(0, 1, (2, 20))
    ref = [(f.U ** xx).matrix @ (f.V ** yy).matrix @ np.append(CORNERS[0], 1.0) for xx, yy in zip(x, y)]
    assert np.allclose(f.points(x, y), np.array(ref)[:, :3], atol=1e-12)


def test_special_case_parallelogram_is_translation():
    f = BeCOTSField.from_corners([0, 0, 0], [0.5, 2, 1], [3.5, 2, 1], [3, 0, 0])
    assert f.kind == "translation"
    assert np.allclose(f.corners, [[0, 0, 0], [0.5, 2, 1], [3.5, 2, 1], [3, 0, 0]])


def test_special_case_coplanar_gives_planar_cots():
    f = BeCOTSField.from_corners([0, 0, 1], [0.2, 2, 1], [3.1, 2.4, 1], [3, 0.1, 1])
    assert f.kind == "cone" and f.is_planar
    assert abs(f.beta - math.pi / 2) < 1e-9
    assert np.abs(f.points(*np.random.default_rng(1).uniform(0, 1, (2, 50)))[:, 2] - 1).max() < 1e-12


def test_special_case_pure_dilation_edges():
    # U without rotation (edges AB ∥ DC) puts F, A, D and F, B, C on lines: the corners are
    # coplanar and the field is the planar COTS whose U is a pure dilation
    g = BeCOTSField.from_controls((0.3, 0.0, -0.2, 0.7), beta=1.0)
    f = BeCOTSField.from_corners(*g.corners)
    assert np.abs(f.corners - g.corners).max() < 1e-9
    assert f.is_planar and abs(f.u[1]) < 1e-12 and f.U.kind == "scaling"


def test_special_case_cylinder_screws():
    g = BeCOTSField("cylinder", np.array([2.0, 0, 0]), np.zeros(3), np.array([0, 0, 1.0]), (1.0, 1.0), (0.2, -2.0))
    f = BeCOTSField.from_corners(*g.corners)
    assert f.kind == "cylinder"
    assert np.abs(f.corners - g.corners).max() < 1e-9
    assert np.abs((f.U @ f.V).matrix - (f.V @ f.U).matrix).max() < 1e-9
    # equal opposite edges leave a family of screw pairs through the corners: the least-rotation
    # one is taken, so its total turn is at most the generating field's
    assert abs(f.u[1]) + abs(f.v[1]) <= abs(g.u[1]) + abs(g.v[1]) + 1e-9


@pytest.mark.parametrize("corners, words", [
    ([[0, 0, 0], [0, 0, 0], [1, 1, 0], [1, 0, 0]], "coincide"),
    ([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], "collinear"),
    ([[0, 0, 0], [0, 1, 0], [1, float("nan"), 0], [1, 0, 0]], "finite"),
])
def test_degenerate_corners_rejected(corners, words):
    with pytest.raises(PleError, match=words):
        BeCOTSField.from_corners(*corners)


# ----- inversion -------------------------------------------------------------------------------------
@settings(max_examples=40, deadline=None)
@given(st.tuples(point, point, point, point), st.floats(0, 1), st.floats(0, 1))
def test_map_then_inverse_returns_the_parameters(pts, x, y):
    f = _field_or_skip(pts)
    q = f.points([x], [y])
    answers = f.inverse(q, tol=1e-7)[0]
    assert any(abs(a - x) < 1e-6 and abs(b - y) < 1e-6 for a, b in answers)
    for a, b in answers:  # every answer is valid: in the square and on the point
        assert -1e-9 <= a <= 1 + 1e-9 and -1e-9 <= b <= 1 + 1e-9
        assert np.linalg.norm(f.points([a], [b]) - q) < 1e-6 * max(1.0, np.abs(q).max())


def test_inverse_of_self_overlapping_map_lists_every_branch():
    # bent tight: U and V turn ~7.7 rad on the cone while U grows and V shrinks: the map overlaps itself
    f = BeCOTSField.from_controls((0.3, 3.0, -0.25, 3.0), beta=0.4)
    rng = np.random.default_rng(2)
    xy = rng.uniform(0, 1, (300, 2))
    pts = f.points(xy[:, 0], xy[:, 1])
    answers = f.inverse(pts)
    assert max(len(a) for a in answers) >= 2
    # brute force: count domain grid cells whose image hits the point (sampled densely)
    for (x, y), ans in zip(xy[:20], answers[:20]):
        assert any(abs(a - x) < 1e-7 and abs(b - y) < 1e-7 for a, b in ans)
        others = [(a, b) for a, b in ans if abs(a - x) > 1e-6 or abs(b - y) > 1e-6]
        for a, b in others:  # different parameters, same point: a genuine self-overlap
            assert np.linalg.norm(f.points([a], [b]) - f.points([x], [y])) < 1e-8


def test_inverse_off_cone_point_has_no_answer():
    f = BeCOTSField.from_corners(*CORNERS)
    q = f.points([0.5], [0.5]) + 0.3 * f.axis
    assert f.inverse(q) == [[]]


# ----- raise, bend, placement -----------------------------------------------------------------------------
def test_raise_project_keep_the_projected_cots():
    f = BeCOTSField.from_corners(*CORNERS)
    xy = np.random.default_rng(3).uniform(0, 1, (2, 30))
    flat = f.projected()
    assert flat.is_planar
    for z in (-1.0, 0.7, 2.0):
        r = f.raised(z)
        assert abs(r.height - z) < 1e-12
        # closest projection of the raised map onto π equals the planar COTS map (Fig. 4.3)
        p = r.points(*xy)
        proj = p - np.outer((p - f.apex) @ f.axis, f.axis)
        assert np.abs(proj - flat.points(*xy)).max() < 1e-9


def test_bend_unbend_and_geodesic_distance_to_apex():
    flat = BeCOTSField.from_corners(*CORNERS).projected()
    xy = np.random.default_rng(4).uniform(0, 1, (2, 30))
    for beta in (0.3, 0.9, 1.3):
        bent = flat.bent(beta)
        assert abs(bent.beta - beta) < 1e-12
        d_flat = np.linalg.norm(flat.points(*xy) - flat.apex, axis=1)
        d_bent = np.linalg.norm(bent.points(*xy) - bent.apex, axis=1)
        assert np.allclose(d_flat, d_bent, rtol=1e-12)  # rolling keeps generator lengths
        assert np.allclose(bent.unbent().points(*xy), flat.points(*xy), atol=1e-9)
    assert np.allclose(flat.bent(math.pi / 2).points(*xy), flat.points(*xy), atol=1e-12)


def test_controls_rebuild_the_field():
    f = BeCOTSField.from_corners(*CORNERS)
    c = f.controls()
    g = BeCOTSField.from_controls(c["warp"], c["beta"], c["placement"])
    assert np.abs(g.corners - f.corners).max() < 1e-9
    moved = f.placed(Rotation(0.4, [1, 2, 3], [1, 0, 0]))
    assert np.allclose(moved.corners, Rotation(0.4, [1, 2, 3], [1, 0, 0]).apply_points(f.corners), atol=1e-9)


# ----- patterns and tiles ---------------------------------------------------------------------------------
def test_tiles_are_pairwise_similar():
    f = BeCOTSField.from_corners(*CORNERS)
    counts = (5, 4)
    s = np.linspace(0, 1, 4)
    gx, gy = (g.reshape(-1) for g in np.meshgrid(s, s))
    tiles = [f.points((i + gx) / counts[0], (j + gy) / counts[1]) for i in range(5) for j in range(4)]
    size = np.linalg.norm(np.ptp(tiles[0], axis=0))
    for t in tiles[1:]:
        assert umeyama_residual(tiles[0], t) < 1e-9 * size * 10
    assert np.allclose(f.tile_corners(2, 3, counts), tiles[2 * 4 + 3][[0, 12, 15, 3]], atol=1e-12)


@pytest.mark.parametrize("power", [2, 3])
def test_pattern_area_volume_closed_form_vs_sum(power):
    f = BeCOTSField.from_corners(*CORNERS)
    counts = (7, 9)
    lu, lv = f.u[0], f.v[0]
    brute = sum(1.7 * math.exp(power * (i * lu / 7 + j * lv / 9)) for i in range(7) for j in range(9))
    assert f.pattern_total(counts, 1.7, power) == pytest.approx(brute, rel=1e-12)
    t = BeCOTSField.from_corners([0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0])
    assert t.pattern_area(counts, 2.0) == pytest.approx(2.0 * 63)


# ----- lattices and BIQ ------------------------------------------------------------------------------------
def _same_biq(lat, rng, n=150, scale=1.0):
    lo, hi = lat.bounds()
    ev = lat.evaluate()
    idx = rng.integers(0, len(ev.center), n)
    c = np.concatenate([rng.uniform(lo, hi, (n, 3)), ev.center[idx] + rng.normal(size=(n, 3)) * ev.radius[idx, None]])
    r = np.concatenate([rng.uniform(0.5, 1.5, n) * lat.mean_radius() * scale, ev.radius[idx] * rng.uniform(0, 2, n)])
    got = biq.query(lat, c, r)
    ref = biq.query(lat, c, r, method="naive")
    assert all(g.path == "becots" for g in got)
    hits = 0
    for g, e in zip(got, ref):
        assert np.array_equal(g.nodes, e.nodes) and np.array_equal(g.beams, e.beams)
        hits += len(e.nodes) + len(e.beams)
    assert hits > 0


@pytest.mark.parametrize("conn", ["triangle", "kagome", "honeycomb"])
def test_biq_matches_brute_force(conn, rng):
    f = BeCOTSField.from_corners(*CORNERS)
    lat = becots_lattice(f, (9, 8), conn, 0.1)
    _same_biq(lat, rng)
    _same_biq(lat, rng, 40, scale=5.0)


def test_biq_self_overlapping_placed_and_layered(rng):
    f = BeCOTSField.from_controls((0.4, 4.0, 0.3, 2.5), beta=0.5)
    lat = becots_lattice(f, (14, 10), "kagome", 0.1, closed=True)
    _same_biq(lat, rng)
    lat.set_placement(Screw(0.7, [0, 1, 1], [1, 2, 0], 0.5))
    lat.set_w(2, Translation([0, 0, 0.8]))
    _same_biq(lat, rng)


@pytest.mark.parametrize("name", ["becots_annulus", "becots_honeycomb", "becots_stack"])
def test_biq_presets(name, rng):
    _same_biq(load_lattice(name, {"nu": 6, "nv": 9} if name != "becots_stack" else {"nu": 5, "nv": 5}), rng, 80)


def test_biq_translation_and_cylinder_kinds(rng):
    t = BeCOTSField.from_corners([0, 0, 0], [0.5, 2, 1], [3.5, 2, 1], [3, 0, 0])
    _same_biq(becots_lattice(t, (6, 5), "kagome", 0.1), rng, 60)
    c = BeCOTSField("cylinder", np.array([2.0, 0, 0]), np.zeros(3), np.array([0, 0, 1.0]), (1.0, 1.0), (0.2, -2.0))
    _same_biq(becots_lattice(c, (7, 7), "triangle", 0.1), rng, 60)


def test_multilevel_filter_removes_a_periodic_subset():
    f = BeCOTSField.from_corners(*CORNERS)
    fine = becots_lattice(f, (8, 8), "triangle", 0.05)
    coarse = becots_lattice(f, (8, 8), "triangle", 0.05, period=2)
    ef, ec = fine.evaluate(), coarse.evaluate()
    # same node positions (as sets), fewer beams, every kept beam is a fine beam
    key = lambda c: set(map(tuple, np.round(c, 9)))  # noqa: E731
    assert key(ef.center) == key(ec.center)
    seg = lambda e: {tuple(sorted((tuple(np.round(e.center[a], 9)), tuple(np.round(e.center[b], 9)))))  # noqa: E731
                     for a, b in e.beam_nodes}
    assert seg(ec) < seg(ef)


def test_stack_pmc_matches_naive(rng):
    f = BeCOTSField.from_corners(*CORNERS)
    for mode in ("raise", "normal"):
        lat = stack_lattice(f, (6, 6), 4, 0.4, mode, "triangle", 0.1)
        ev = lat.evaluate()
        idx = rng.integers(0, len(ev.center), 60)
        pts = np.concatenate([ev.center[idx] + rng.normal(size=(60, 3)) * ev.radius[idx, None] * 1.5,
                              rng.uniform(*lat.bounds(), (30, 3))])
        got = stack_pmc(lat, pts)
        ref = biq.naive_any(lat, pts, np.zeros(len(pts)))
        assert np.array_equal(got, ref) and ref.any()


def test_changed_u_is_detected():
    lat = becots_lattice(BeCOTSField.from_corners(*CORNERS), (4, 4), "triangle")
    lat.set_u(4, Translation([1, 0, 0]))
    with pytest.raises(PleError, match="changed after set_becots"):
        becots_of(lat)


# ----- constant-radius connectors ------------------------------------------------------------------------
def test_constant_radius_connectors_are_congruent_per_class():
    lat = load_lattice("becots_constant_radius", {"nu": 5, "nv": 5})
    classes, beams = constant_radius_connectors(lat, 0.15, 0.06)
    assert sum(len(c.instances) for c in classes) == lat.node_count()
    inner = [c for c in classes if len(c.key[1]) == 3]
    assert inner and max(len(c.instances) for c in inner) >= 9
    evc = lat.evaluate().center
    for cls in classes:
        size = np.ptp(cls.points, axis=0).max()
        for row in cls.nodes:
            # rebuild this connector's points from scratch and align independently (Kabsch)
            mine = _connector_of(lat, evc, row, 0.15, 0.06)
            m = kabsch(cls.points, mine)
            aligned = cls.points @ m[:3, :3].T + m[:3, 3]
            assert np.linalg.norm(aligned - mine, axis=1).max() <= 1e-9 * size
            assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
        # the Boolean connector meshes too: rebuild two instances and compare vertex sets
        for row in cls.nodes[:2]:
            mesh = _connector_of(lat, evc, row, 0.15, 0.06, mesh=True)
            m = kabsch(cls.points, _connector_of(lat, evc, row, 0.15, 0.06))
            moved = cls.mesh.vertices @ m[:3, :3].T + m[:3, 3]
            assert len(mesh.vertices) == len(cls.mesh.vertices) and mesh.is_watertight
            assert cKDTree(mesh.vertices).query(moved)[0].max() <= 1e-9 * size
    assert np.allclose(np.linalg.norm(beams["end"] - beams["start"], axis=1) > 0, True)


def _connector_of(lat, centers, row, radius, beam_radius, mesh=False):
    from ple.meshing.connectors import connector_mesh, connector_points

    ev = lat.evaluate()
    me = int(np.nonzero((ev.node_index == row).all(axis=1))[0][0])
    inc = []
    for (bi, (s, e)) in zip(ev.beam_index, ev.beam_nodes):
        if s == me:
            inc.append((bi[3], 0, e))
        elif e == me:
            inc.append((bi[3], 1, s))
    inc.sort()
    dirs = np.array([(centers[o] - centers[me]) / np.linalg.norm(centers[o] - centers[me]) for _, _, o in inc])
    if mesh:
        return connector_mesh(centers[me], dirs, radius, beam_radius)
    return connector_points(centers[me], dirs, radius, beam_radius)


# ----- IR and CLI ------------------------------------------------------------------------------------------
def test_ir_round_trip():
    for name in ("becots_triangle", "becots_annulus", "becots_honeycomb", "becots_stack"):
        lat = load_lattice(name)
        d = json.loads(json.dumps(lattice_to_dict(lat, resolved=False)))
        assert "becots" in d and "U" not in d
        back = lattice_from_dict(d)
        assert np.abs(back.evaluate().center - lat.evaluate().center).max() < 1e-9
        assert back.becots.counts == lat.becots.counts


def test_ir_errors_name_the_field():
    lat = becots_lattice(BeCOTSField.from_corners(*CORNERS), (3, 3), "triangle")
    d = lattice_to_dict(lat, resolved=False)
    d["becots"]["corners"][1] = d["becots"]["corners"][0]
    with pytest.raises(PleError, match="becots.*coincide"):
        lattice_from_dict(d)
    d["becots"]["counts"] = [3]
    with pytest.raises(PleError, match="becots.counts"):
        lattice_from_dict(d)


def _ple(*args, cwd):
    return subprocess.run([sys.executable, "-m", "ple.cli", *args], cwd=cwd, capture_output=True, text=True)


def test_cli_eval_map_inverse(tmp_path: Path):
    lat = Lattice()
    a = lat.add_node([0, 0, 0], 0.1)
    lat.add_beam(a, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    set_field(lat, BeCOTSField.from_corners(*CORNERS), (4, 3))
    save_ir(lat, tmp_path / "b.json", resolved=False)
    assert "becots" in json.loads((tmp_path / "b.json").read_text())
    out = _ple("eval", "b.json", "--out", "e.npz", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    e = np.load(tmp_path / "e.npz")
    f = BeCOTSField.from_corners(*CORNERS)
    ij = e["node_index"][:, :2]
    assert np.allclose(e["center"], f.points(ij[:, 0] / 4, ij[:, 1] / 3), atol=1e-9)
    np.save(tmp_path / "uv.npy", np.array([[0.0, 0], [0, 1], [1, 1], [1, 0], [0.25, 0.6]]))
    corners = " ".join(",".join(str(v) for v in p) for p in CORNERS)
    assert _ple("becots", "map", "--corners", corners, "--uv", "uv.npy", "--out", "p.npy", cwd=tmp_path).returncode == 0
    p = np.load(tmp_path / "p.npy")
    assert np.allclose(p[:4], CORNERS, atol=1e-9)
    assert _ple("becots", "inverse", "--corners", corners, "--points", "p.npy", "--out", "uv.json",
                cwd=tmp_path).returncode == 0
    ans = json.loads((tmp_path / "uv.json").read_text())
    assert any(np.allclose(a, [0.25, 0.6], atol=1e-9) for a in ans[4])
    bad = _ple("becots", "map", "--corners", "0,0,0 0,0,0 1,1,0 1,0,0", "--uv", "uv.npy", "--out", "q.npy",
               cwd=tmp_path)
    assert bad.returncode == 2 and "coincide" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "q.npy").exists()


def test_biq_queries_on_the_axis_and_around_the_apex(rng):
    # special cases of the log-polar bound: balls touching the axis (full circle of angles) and
    # balls containing the apex F (unbounded rho); the lattice wraps around its cone
    f = BeCOTSField.from_controls((0.5, 4.0, 0.4, 2.0), beta=0.3)
    lat = becots_lattice(f, (10, 8), "kagome", 0.2)
    t = rng.uniform(-3, 3, 120)
    c = f.apex + t[:, None] * f.axis + rng.normal(size=(120, 3)) * 0.3
    r = rng.uniform(0.1, 3, 120)
    got, ref = biq.query(lat, c, r), biq.query(lat, c, r, method="naive")
    assert all(np.array_equal(g.nodes, e.nodes) and np.array_equal(g.beams, e.beams) for g, e in zip(got, ref))
    assert sum(len(e.nodes) for e in ref) > 100


def test_stale_becots_falls_back_to_the_general_path(rng):
    lat = becots_lattice(BeCOTSField.from_corners(*CORNERS), (6, 5), "triangle", 0.1).with_counts(4, 4, 1)
    c, r = rng.uniform(*lat.bounds(), (40, 3)), np.full(40, 0.5)
    got, ref = biq.query(lat, c, r), biq.query(lat, c, r, method="naive")
    assert all(g.path != "becots" for g in got)
    assert all(np.array_equal(g.nodes, e.nodes) and np.array_equal(g.beams, e.beams) for g, e in zip(got, ref))


@settings(max_examples=15, deadline=None)
@given(st.tuples(point, point, point, point), st.sampled_from(["triangle", "kagome", "honeycomb"]),
       st.integers(0, 2**31))
def test_biq_matches_brute_force_on_random_corners(pts, conn, seed):
    f = _field_or_skip(pts)
    lat = becots_lattice(f, (5, 4), conn, 0.1)
    _same_biq(lat, np.random.default_rng(seed), 30, scale=2.0)
