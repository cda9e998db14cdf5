"""Graded thickness: radius fields multiply node radii in the one evaluation; queries stay exact
(RangeFinder vs every element); graded meshes are watertight with the Monte Carlo volume."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from lattices import KINDS, random_lattice
from ple.algebra.elements import ball_ball_interfere, ball_beam_interfere
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.body import BodyFilter, SurfaceDistanceField
from ple.io.bodyfile import body_from_trimesh
from ple.measure.integrals import lattice_measures
from ple.meshing.tessellate import tessellate
from ple.model.grading import FunctionField, GridField, LinearGradient
from ple.program.sources import load_lattice
from ple.queries import biq


def test_gradient_from_r_to_2r_is_reproduced_at_the_nodes():
    lat = load_lattice("cubic", {"n": 8, "radius": 0.1})
    a, b = np.array([0.0, 0, 0]), np.array([7.0, 7, 7])
    lat.set_radius_field(LinearGradient(a, b, 1.0, 2.0))
    ev = lat.evaluate()
    t = np.clip((ev.center - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    np.testing.assert_allclose(ev.radius, 0.1 * (1 + t), rtol=0, atol=1e-9)
    assert ev.radius.min() == pytest.approx(0.1) and ev.radius.max() == pytest.approx(0.2)
    # node_balls (random access) agrees with the region evaluation
    c, r = lat.node_balls(ev.node_index[::7])
    np.testing.assert_allclose(r, ev.radius[::7], rtol=0, atol=1e-15)
    # the CLI flag gives the same radii
    assert lat.mean_radius() == pytest.approx(ev.radius.mean(), rel=1e-12)


def test_grid_field_reproduces_a_linear_function_and_function_fields_are_checked():
    g = np.linspace(0, 1, 5)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    field = GridField(1 + x + 2 * y + 0.5 * z, (0, 0, 0), (2, 2, 2))
    p = np.random.default_rng(0).uniform(0, 2, (100, 3))
    np.testing.assert_allclose(field.factors(p), 1 + p[:, 0] / 2 + p[:, 1] + p[:, 2] / 4, atol=1e-12)
    lat = load_lattice("cubic", {"n": 3})
    lat.set_radius_field(FunctionField(lambda q: 1 + q[:, 0], bound=2.0))
    with pytest.raises(PleError, match=r"factor 3\.0 .* is not in \(0, 2\]"):
        lat.evaluate()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_graded_queries_are_exact(seed):
    rng = np.random.default_rng(seed)
    lat = random_lattice(rng, [KINDS[(seed + a) % 5] for a in range(3)], (6, 5, 4), 0.6, 0.08)
    full = lat.evaluate()
    lo, hi = full.center.min(axis=0), full.center.max(axis=0)
    lat.set_radius_field(LinearGradient(lo, hi, 0.5, 2.5))
    ev = lat.evaluate()
    qc = rng.uniform(lo, hi, (300, 3))
    qr = rng.uniform(0.0, 0.15, 300)
    res = biq.query(lat, qc, qr, method="rangefinder")
    for q in range(len(qc)):  # every element, exactly (independent of the candidate search)
        nodes = np.flatnonzero(ball_ball_interfere(ev.center, ev.radius, qc[q], qr[q]))
        a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
        beams = np.flatnonzero(ball_beam_interfere(qc[q], qr[q], ev.center[a], ev.radius[a], ev.center[b],
                                                   ev.radius[b]))
        assert sorted(map(tuple, res[q].nodes.tolist())) == sorted(map(tuple, ev.node_index[nodes].tolist()))
        assert sorted(map(tuple, res[q].beams.tolist())) == sorted(map(tuple, ev.beam_index[beams].tolist()))
    # grading changes the answer (the test can fail): the steady radii give other hits
    steady = biq.query(lat.bounding_lattice(), qc, qr * 0, method="rangefinder")
    assert sum(len(x.nodes) for x in steady) != sum(len(x.nodes) for x in biq.query(lat, qc, qr * 0))


def test_graded_mesh_is_watertight_with_the_monte_carlo_volume():
    lat = load_lattice("cubic", {"n": 4, "radius": 0.12})
    lat.set_radius_field(LinearGradient((0, 0, 0), (3, 3, 3), 1.0, 2.0))
    mesh = tessellate(lat)
    assert mesh.is_watertight and mesh.is_volume
    rng = np.random.default_rng(1)
    lo, hi = mesh.bounds
    n = 400_000
    p = rng.uniform(lo, hi, (n, 3))
    ev = lat.evaluate()
    # brute force: every ball and beam of the graded evaluation, each tested on the points not yet
    # inside whose x lies within its box (the points sorted by x once)
    order = np.argsort(p[:, 0], kind="stable")
    x = p[order, 0]
    inside = np.zeros(n, dtype=bool)

    def near(x0: float, x1: float) -> np.ndarray:
        rows = order[np.searchsorted(x, x0 - 1e-9):np.searchsorted(x, x1 + 1e-9, "right")]
        return rows[~inside[rows]]

    for c, r in zip(ev.center, ev.radius):
        rows = near(c[0] - r, c[0] + r)
        inside[rows] = np.einsum("ij,ij->i", p[rows] - c, p[rows] - c) <= r * r
    for a, b in ev.beam_nodes:
        ca, ra, cb, rb = ev.center[a], ev.radius[a], ev.center[b], ev.radius[b]
        rows = near(min(ca[0] - ra, cb[0] - rb), max(ca[0] + ra, cb[0] + rb))
        inside[rows] = ball_beam_interfere(p[rows], 0.0, ca, ra, cb, rb)
    frac = inside.mean()
    box = np.prod(hi - lo)
    mc, se = frac * box, np.sqrt(frac * (1 - frac) / n) * box
    assert 3 * se < 0.01 * mc
    assert mesh.volume == pytest.approx(mc, rel=0.01)
    assert lattice_measures(lat)["volume"] == pytest.approx(mc, rel=0.01)


def test_surface_distance_grading_and_the_cli(tmp_path, capsys):
    mesh = trimesh.creation.box(extents=(6, 6, 6))
    mesh.apply_translation((3, 3, 3))
    body = body_from_trimesh(mesh)
    lat = load_lattice("cubic", {"n": 7, "radius": 0.1})
    lat.set_radius_field(SurfaceDistanceField(body, 1.5, 2.0, 1.0))
    ev = lat.with_filter(BodyFilter(body, "any")).evaluate()
    d = np.min(np.concatenate([ev.center, 6 - ev.center], axis=1), axis=1)  # inside a box: the nearest face
    d = np.where(np.all((ev.center > 0) & (ev.center < 6), axis=1), d, 0.0)
    np.testing.assert_allclose(ev.radius, 0.1 * (2.0 - np.minimum(np.abs(d), 1.5) / 1.5), atol=1e-12)
    path = tmp_path / "box.stl"
    mesh.export(path)
    out = tmp_path / "e.npz"
    assert main(["eval", "cubic", "--param", "n=7", "--body", str(path), "--fill", "any",
                 "--grade", "surface:1.5:2:1", "--out", str(out)]) == 0
    with np.load(out) as got:
        np.testing.assert_allclose(got["radius"], ev.radius, atol=1e-12)
    assert main(["info", "cubic", "--grade", "surface:1:2:1"]) == 2
    assert "needs --body" in capsys.readouterr().err


def _round_trip(lat, path):
    from ple.io.irfile import load_ir, save_ir

    save_ir(lat, path)
    back = load_ir(path)
    np.testing.assert_allclose(back.evaluate().radius, lat.evaluate().radius, rtol=0, atol=1e-12)
    save_ir(back, path.with_name("again.json"))  # the data is a fixed point of save/load
    assert json.loads(path.read_text()) == json.loads(path.with_name("again.json").read_text())
    return json.loads(path.read_text())["grade"]


def test_graded_lattices_round_trip_as_data(tmp_path):
    lat = load_lattice("cubic", {"n": 4})
    lat.set_radius_field(LinearGradient((0, 0, 0), (3, 3, 3), 1, 2))
    assert _round_trip(lat, tmp_path / "lin.json") == {"kind": "linear", "a": [0, 0, 0], "b": [3, 3, 3],
                                                       "f0": 1.0, "f1": 2.0}
    g = np.random.default_rng(3).uniform(0.5, 2.0, (3, 4, 2))
    lat.set_radius_field(GridField(g, (-1, 0, 0), (4, 3, 3.5)))
    data = _round_trip(lat, tmp_path / "grid.json")
    assert data["kind"] == "grid" and np.array_equal(np.array(data["values"]), g)
    box = trimesh.creation.box(extents=(3.2, 3.1, 3.3))
    box.apply_translation((1.5, 1.5, 1.5))
    box.export(tmp_path / "box.stl")
    from ple.io.bodyfile import load_body

    body = load_body(tmp_path / "box.stl")
    lat = load_lattice("cubic", {"n": 4}).with_filter(BodyFilter(body, "any"))
    lat.set_radius_field(SurfaceDistanceField(body, 1.2, 2.0, 1.0))
    assert _round_trip(lat, tmp_path / "surf.json") == {"kind": "surface", "depth": 1.2, "f_surface": 2.0,
                                                        "f_deep": 1.0}


def test_function_fields_and_foreign_bodies_are_not_data(tmp_path):
    from ple.io.irfile import save_ir

    lat = load_lattice("cubic", {"n": 3})
    lat.set_radius_field(FunctionField(lambda p: 1 + 0 * p[:, 0], 1.0))
    with pytest.raises(PleError, match="grade: a FunctionField cannot be written as data"):
        save_ir(lat, tmp_path / "g.json")
    assert not (tmp_path / "g.json").exists()
    body = body_from_trimesh(trimesh.creation.box(extents=(2, 2, 2)))
    lat.set_radius_field(SurfaceDistanceField(body, 1.0))
    with pytest.raises(PleError, match="lattice's own body"):
        save_ir(lat, tmp_path / "g.json")


BASE = {"format": "ple-lattice/1", "nodes": [{"center": [0, 0, 0], "radius": 0.1}],
        "U": {"count": 3, "similarity": {"kind": "translation", "vector": [1, 0, 0]}}}


@pytest.mark.parametrize("grade, message", [
    ({"kind": "ramp"}, "grade.kind: expected one of linear, grid, surface, got 'ramp'"),
    ([1, 2], "grade: expected an object with kind"),
    ({"kind": "linear", "a": [0, 0, 0]}, "grade.b: missing"),
    ({"kind": "linear", "a": [0, "x", 0], "b": [1, 1, 1]}, "grade.a[1]: expected a finite number"),
    ({"kind": "linear", "a": [0, 0, 0], "b": [1, 1, 1], "f0": -1}, "grade.f0: must be positive"),
    ({"kind": "linear", "a": [0, 0, 0], "b": [1, 1, 1], "slope": 2}, "grade.slope: unknown field"),
    ({"kind": "linear", "a": [1, 1, 1], "b": [1, 1, 1]}, "grade: a gradient needs two distinct finite points"),
    ({"kind": "grid", "lo": [0, 0, 0], "hi": [1, 1, 1], "values": [[[1, 1], [1, 1]], [[1, 1], [1]]]},
     "grade.values[1][1]: expected 2 numbers"),
    ({"kind": "grid", "lo": [0, 0, 0], "hi": [1, 1, 1], "values": [[[1, 1], [1, 1]], [[1, 0], [1, 1]]]},
     "grade.values[1][0][1]: must be positive"),
    ({"kind": "grid", "lo": [0, 0, 0], "hi": [0, 1, 1], "values": [[[1, 1], [1, 1]], [[1, 1], [1, 1]]]},
     "grade: grid field box: hi must exceed lo"),
    ({"kind": "surface", "depth": 1.0}, "grade: a surface grade needs a body filter"),
    ({"kind": "surface", "depth": 0}, "grade.depth: must be positive"),
])
def test_grade_errors_name_the_field(grade, message):
    from ple.filters.ir import lattice_from_ir

    with pytest.raises(PleError) as err:
        lattice_from_ir({**BASE, "grade": grade})
    assert str(err.value).startswith(message), str(err.value)


def test_ple_ir_writes_the_grade(tmp_path):
    out = tmp_path / "g.json"
    assert main(["ir", "cubic", "--param", "n=4", "--grade", "0,0,0:3,3,3:1:2", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["grade"]["kind"] == "linear"
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["eval", str(out), "--out", str(a)]) == 0
    assert main(["eval", "cubic", "--param", "n=4", "--grade", "0,0,0:3,3,3:1:2", "--out", str(b)]) == 0
    with np.load(a) as x, np.load(b) as y:
        np.testing.assert_allclose(x["radius"], y["radius"], rtol=0, atol=1e-12)
