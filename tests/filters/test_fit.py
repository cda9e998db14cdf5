"""Symmetric implicit fields fitted from meshes (004_ §3.2): winding numbers against analytic
inside/outside, FFT field grids against direct evaluation, the chosen order's level set against
the analytic sphere, T_d invariance, and ``ple fit`` as a filter."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from ple.cli.common import parse_implicit
from ple.cli.main import main
from ple.filters.fit import field_grid, fit_mesh, inside_grid, winding_numbers
from ple.filters.implicit import TD_OPERATORS, FourierField, sample_grid
from ple.program.sources import load_lattice
from scipy.spatial import cKDTree

R = 0.3


@pytest.fixture(scope="module")
def sphere():
    return trimesh.creation.icosphere(3, R)


@pytest.fixture(scope="module")
def fitted(sphere):
    return fit_mesh(sphere.vertices, sphere.faces, bound=0.035, orders=(8, 16, 32))


def test_winding_numbers_inside_outside(sphere):
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.5, 0.5, (3000, 3))
    d = np.linalg.norm(p, axis=1)
    w = winding_numbers(sphere.vertices, sphere.faces, p)
    # the icosphere's chords sag by < 0.3 (1 - cos(edge/2R)): classify only clear points
    clear = np.abs(d - R) > 0.01
    assert np.all((w[clear] > 0.5) == (d[clear] < R))
    assert np.allclose(w[d < R - 0.01], 1.0, atol=1e-9) and np.allclose(w[d > R + 0.01], 0.0, atol=1e-9)
    # a soup of two copies winds twice; a reversed copy cancels
    f2 = np.concatenate([sphere.faces, sphere.faces])
    assert np.allclose(winding_numbers(sphere.vertices, f2, [[0, 0, 0]]), 2.0)
    f0 = np.concatenate([sphere.faces, sphere.faces[:, ::-1]])
    assert np.allclose(winding_numbers(sphere.vertices, f0, [[0.05, 0.0, 0.1]]), 0.0, atol=1e-12)
    g = inside_grid(sphere.vertices, sphere.faces, 16)
    t = -0.5 + np.arange(16) / 16
    pts = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1)
    assert np.array_equal(g, np.linalg.norm(pts, axis=-1) < R)


def test_field_grid_is_direct_evaluation(fitted):
    fld = fitted.field
    assert np.allclose(field_grid(fld, 24 if fld.n <= 24 else fld.n), sample_grid(fld, 24 if fld.n <= 24 else fld.n),
                       atol=1e-9)


def _crossings(fld, m):
    """Level-set points from direct evaluation on a closed (M+1)³ grid (independent of field_grid)."""
    t = np.linspace(-0.5, 0.5, m + 1)
    pts = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1)
    val = fld(pts.reshape(-1, 3)).reshape(pts.shape[:3])
    out = []
    for ax in range(3):
        a = [slice(None)] * 3
        b = [slice(None)] * 3
        a[ax], b[ax] = slice(0, -1), slice(1, None)
        va, vb = val[tuple(a)], val[tuple(b)]
        c = (va < 0) != (vb < 0)
        w = va[c] / (va[c] - vb[c])
        out.append(pts[tuple(a)][c] + w[:, None] * (pts[tuple(b)][c] - pts[tuple(a)][c]))
    return np.concatenate(out)


def test_chosen_order_meets_the_bound_against_the_analytic_sphere(fitted):
    assert fitted.met and fitted.order == min(n for n, h in fitted.tried if h <= fitted.bound)
    assert all(h > fitted.bound for n, h in fitted.tried if n < fitted.order)
    pts = _crossings(fitted.field, 90)
    slack = fitted.sampling_error
    # level set -> sphere, exactly
    assert np.abs(np.linalg.norm(pts, axis=1) - R).max() <= fitted.bound + slack
    # sphere -> level set: every direction of the sphere has a level-set point within the bound
    u = np.random.default_rng(1).normal(size=(4000, 3))
    u = R * u / np.linalg.norm(u, axis=1)[:, None]
    assert cKDTree(pts).query(u)[0].max() <= fitted.bound + slack


def test_fitted_field_has_td_symmetry(fitted):
    x = np.random.default_rng(2).uniform(-0.5, 0.5, (200, 3))
    base = fitted.field(x)
    for q in TD_OPERATORS:
        assert np.allclose(fitted.field(x @ q.T), base, atol=1e-9)


def test_ple_fit_cli_writes_a_filter(tmp_path, sphere, capsys):
    mesh = sphere.copy()
    mesh.apply_scale(2.0)  # 0.6 radius: outside the cell until --normalize
    mesh.apply_translation([3, 3, 3])
    path = tmp_path / "ball.stl"
    mesh.export(path)
    out = tmp_path / "ball.npz"
    assert main(["fit", str(path), "--out", str(out)]) == 2  # outside the cell: a named error
    assert "cell" in capsys.readouterr().err
    assert main(["fit", str(path), "--out", str(out), "--normalize", "--bound", "0.04", "--orders", "8,16"]) == 0
    rep = json.loads(capsys.readouterr().out.split("\nnote:")[0])
    assert rep["met"] and rep["order"] in (8, 16)
    fld = FourierField.load(out)
    assert fld.symmetric and fld.n == rep["order"]
    flt = parse_implicit(f"fourier:file={out},cell=4")
    lat = load_lattice("cubic")
    ev = lat.evaluate()
    keep = flt.node_mask(lat, ev.node_index, ev.center, ev.radius)
    # independent truth: a ball of radius 0.45 per 4-unit cell (scaled mesh), periodic
    local = (ev.center / 4 + 0.5) % 1.0 - 0.5
    d = np.linalg.norm(local, axis=1)
    clear = np.abs(d - 0.45) > 0.04 + rep["sampling_error"]
    assert np.array_equal(keep[clear], d[clear] < 0.45)
