"""Signed distance fitted from closed meshes (004_ §3.2's sampled SDF): point-triangle distances
against trimesh's and against dense samples of each triangle, the sampled grid against the
analytic sphere, the fitted field reproducing the sphere's distance and a regular tetrahedron's
(a T_d-symmetric solid) with the seed's error measure (Hausdorff distance of the level set to
the mesh), and ``ple fit --distance`` (refusing open and flat meshes with exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from ple.cli.main import main
from ple.filters.fit import closest_on_triangles, distance_grid, fit_mesh, grid_points, mesh_distance
from ple.filters.implicit import TD_OPERATORS, FourierField

R = 0.3
SPHERE_TOL = 0.004  # |Φ(x) - (|x| - R)| for |x| <= 0.45 at order 32: mesh sag plus truncation
TET = 0.35 * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)  # T_d's own tetrahedron


@pytest.fixture(scope="module")
def sphere():
    return trimesh.creation.icosphere(4, R)


@pytest.fixture(scope="module")
def tetrahedron():
    mesh = trimesh.Trimesh(TET, [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
    mesh.fix_normals()
    return mesh


def test_closest_points_against_dense_triangle_samples():
    rng = np.random.default_rng(0)
    tri = rng.normal(size=(300, 3, 3))
    tri[:20, 2] = tri[:20, 0] + 2 * (tri[:20, 1] - tri[:20, 0])  # degenerate: collinear corners
    p = rng.normal(size=(300, 3)) * 2
    x = closest_on_triangles(p, tri[:, 0], tri[:, 1], tri[:, 2])
    d = np.linalg.norm(x - p, axis=1)
    u, v = np.meshgrid(np.linspace(0, 1, 60), np.linspace(0, 1, 60))
    keep = u + v <= 1
    bary = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], axis=1)  # (S, 3)
    samples = np.einsum("sc,tck->tsk", bary, tri)
    dense = np.linalg.norm(samples - p[:, None], axis=2).min(axis=1)
    assert np.all(d <= dense + 1e-12)  # never farther than any point of the triangle
    assert np.all(dense - d <= 0.03 * np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1) + 0.06)  # sample spacing
    # x lies on its triangle: inside the plane and within the barycentric range
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    ok = slice(20, None)
    sol = np.linalg.lstsq(np.stack([e1[ok], e2[ok]], axis=2)[0], (x[ok] - tri[ok, 0])[0], rcond=None)[0]
    assert sol.min() >= -1e-9 and sol.sum() <= 1 + 1e-9


@pytest.mark.parametrize("name", ["sphere", "tetrahedron"])
def test_mesh_distance_equals_trimesh(name, request):
    mesh = request.getfixturevalue(name)
    p = np.random.default_rng(1).uniform(-0.5, 0.5, (3000, 3))
    _, want, _ = trimesh.proximity.closest_point(mesh, p)
    assert np.allclose(mesh_distance(mesh.vertices, mesh.faces, p), want, atol=1e-12)


def test_distance_grid_is_the_spheres_signed_distance(sphere):
    g = distance_grid(sphere.vertices, sphere.faces, 16)
    want = np.linalg.norm(grid_points(16), axis=-1) - R
    sag = R * (1 - np.cos(np.radians(4.0)))  # icosphere(4): edges under 8° of arc
    assert np.abs(g - want).max() <= sag


@pytest.fixture(scope="module")
def sphere_fit(sphere):
    return fit_mesh(sphere.vertices, sphere.faces, bound=0.005, orders=(16, 32), distance=True)


def test_fit_reproduces_the_spheres_distance(sphere_fit):
    fit = sphere_fit
    assert fit.samples == "signed distance" and fit.field.symmetric and fit.order == 32
    x = np.random.default_rng(2).uniform(-0.5, 0.5, (20000, 3))
    x = x[np.linalg.norm(x, axis=1) <= 0.45]
    assert np.abs(fit.field(x) - (np.linalg.norm(x, axis=1) - R)).max() <= SPHERE_TOL
    # the seed's measure: the level set within the Hausdorff distance it reports (its sampling error aside)
    assert fit.hausdorff <= SPHERE_TOL + fit.sampling_error
    assert fit.residual["max_near_surface"] <= 1e-3


def test_distance_fit_beats_inside_outside_on_the_sphere(sphere, sphere_fit):
    """004_ §3.2: sampled SDF inputs give a smoother, closer approximation than ±1 samples."""
    ref = fit_mesh(sphere.vertices, sphere.faces, bound=1e-9, orders=(32,))
    u = np.random.default_rng(3).normal(size=(3000, 3))
    u = R * u / np.linalg.norm(u, axis=1)[:, None]
    grad = 1.0  # |∇(|x| - R)|: the distance fit's value on the sphere is its distance error
    assert np.abs(sphere_fit.field(u)).max() / grad <= SPHERE_TOL
    assert sphere_fit.hausdorff <= ref.hausdorff


def test_fit_of_a_td_symmetric_tetrahedron(tetrahedron):
    fit = fit_mesh(tetrahedron.vertices, tetrahedron.faces, bound=0.02, orders=(16, 32), distance=True)
    assert fit.met and fit.order == 32 and fit.hausdorff <= 0.02
    rng = np.random.default_rng(4)
    x = rng.uniform(-0.35, 0.35, (20000, 3))
    # inside a convex solid the signed distance is the largest signed distance to the face planes
    n = tetrahedron.face_normals
    h = np.einsum("ij,ij->i", n, tetrahedron.vertices[tetrahedron.faces[:, 0]])
    sd = (x @ n.T - h).max(axis=1)
    deep = sd < -0.03
    assert deep.sum() > 1000 and np.abs(fit.field(x[deep]) - sd[deep]).max() <= 0.015
    for q in TD_OPERATORS:  # the field keeps the solid's symmetry
        assert np.allclose(fit.field(x[:300] @ q.T), fit.field(x[:300]), atol=1e-9)


def test_ple_fit_distance_cli(tmp_path, sphere, capsys):
    path = tmp_path / "ball.stl"
    sphere.export(path)
    out = tmp_path / "ball.npz"
    assert main(["fit", str(path), "--distance", "--orders", "16", "--bound", "0.02", "--out", str(out)]) == 0
    rep = json.loads(capsys.readouterr().out.split("\nnote:")[0])
    assert rep["samples"] == "signed distance" and rep["met"] and rep["order"] == 16
    assert set(rep["distance_residual"]) == {"rms", "max", "max_near_surface"}
    fld = FourierField.load(out)
    x = np.random.default_rng(5).uniform(-0.3, 0.3, (2000, 3))
    assert np.abs(fld(x) - (np.linalg.norm(x, axis=1) - R)).max() <= 0.02


@pytest.mark.parametrize("mesh,reason", [
    (lambda s: trimesh.Trimesh(s.vertices, s.faces[:-10]), "not closed"),
    (lambda s: trimesh.Trimesh([[0, 0, 0], [0.3, 0, 0], [0, 0.3, 0]], [[0, 1, 2], [0, 2, 1]], process=False),
     "encloses no volume"),  # closed (each edge twice) around nothing
])
def test_ple_fit_distance_refuses_open_and_flat_meshes(tmp_path, sphere, capsys, mesh, reason):
    path = tmp_path / "bad.stl"
    mesh(sphere).export(path)
    out = tmp_path / "bad.npz"
    assert main(["fit", str(path), "--distance", "--orders", "8", "--out", str(out)]) == 2
    assert reason in capsys.readouterr().err and not out.exists()
