"""Graded thickness: radius fields multiply node radii in the one evaluation; queries stay exact
(RangeFinder vs every element); graded meshes are watertight with the Monte Carlo volume."""

from __future__ import annotations

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
    inside = np.zeros(n, dtype=bool)
    for s in range(0, n, 20_000):  # brute force: every ball and beam of the graded evaluation
        q = p[s:s + 20_000]
        hit = np.zeros(len(q), dtype=bool)
        for c, r in zip(ev.center, ev.radius):
            hit |= np.einsum("ij,ij->i", q - c, q - c) <= r * r
        a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
        rows = np.flatnonzero(~hit)
        for k in range(len(a)):
            if rows.size == 0:
                break
            m = ball_beam_interfere(q[rows], 0.0, ev.center[a[k]], ev.radius[a[k]], ev.center[b[k]], ev.radius[b[k]])
            hit[rows[m]] = True
            rows = rows[~m]
        inside[s:s + 20_000] = hit
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


def test_a_graded_lattice_is_not_written_as_steady_data(tmp_path):
    from ple.io.irfile import save_ir

    lat = load_lattice("cubic", {"n": 3})
    lat.set_radius_field(LinearGradient((0, 0, 0), (2, 2, 2), 1, 2))
    with pytest.raises(PleError, match="graded lattice"):
        save_ir(lat, tmp_path / "g.json")
    assert not (tmp_path / "g.json").exists()
