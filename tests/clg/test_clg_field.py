"""Fitted symmetric fields as CLG solids (ple.clg.field): a primitive whose material replaces it
by {Φ ≤ level} is X ∩ {Φ ≤ level}, in the world frame or the primitive's own frame. PMC against
the Fourier series summed directly (every term, no orbits) over every chunk copy; the value's
magnitude is a safe distance bound; the inline ple-clg/1 data round-trips; `ple fit --out .json`
writes that data."""

from __future__ import annotations

import json

import numpy as np
import pytest
from ple.clg.field import FieldSolid, field_to_dict
from ple.clg.ir import clg_from_dict, clg_to_dict
from ple.clg.model import CLG, Ball, Beam, Material
from ple.clg.query import compiled
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.fit import fit_mesh
from ple.filters.implicit import FourierField
from ple.model.ir import lattice_from_dict

OCTA_V = 0.4 * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTA_F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


@pytest.fixture(scope="module")
def octahedron() -> FourierField:
    return fit_mesh(OCTA_V, OCTA_F, bound=0.05, orders=(8,)).field


def series(fld: FourierField, x: np.ndarray) -> np.ndarray:
    """Re Σ c_f exp(2πi f·x) over every stored term: the field by its definition."""
    return np.real(np.exp(2j * np.pi * (x @ fld.freqs.T)) @ fld.coeffs)


def pattern():
    return lattice_from_dict({"format": "ple-lattice/1", "nodes": [{"id": "a", "center": [0, 0, 0], "radius": 0.45}],
                              "beams": [{"from": "a", "to": "a", "offset": [1, 0, 0]}],
                              "U": {"count": 3, "similarity": {"kind": "translation", "vector": [1.0, 0, 0]}},
                              "V": {"count": 2, "similarity": {"kind": "translation", "vector": [0, 1.1, 0]}}})


def test_fitted_shape_in_every_ball_against_the_series(octahedron):
    lat = pattern()
    clg = CLG(lat, {"c": Ball("a", material="octa")}, "c", {"octa": Material(FieldSolid(octahedron), "beam")})
    rng = np.random.default_rng(0)
    p = rng.uniform([-0.6, -0.6, -0.6], [2.6, 1.7, 0.6], (20000, 3))
    got = compiled(clg).pmc(p)
    # reference: some copy's ball holds p and the series at (p - c) / r (the ball's frame) is ≤ 0
    ref = np.zeros(len(p), bool)
    for i in range(3):
        for j in range(2):
            c, r = lat.node_balls(np.array([[i, j, 0, 0]]))
            loc = (p - c[0]) / r[0]
            rows = np.flatnonzero(np.linalg.norm(loc, axis=1) <= 1)  # the series where the ball holds p
            ref[rows] |= series(octahedron, loc[rows]) <= 0
    assert got.sum() > 500 and np.array_equal(got, ref)


def test_world_frame_field_in_beams_and_its_distance_bound(octahedron):
    lat = pattern()
    fld = FourierField(octahedron.freqs, octahedron.coeffs, octahedron.n, cell=0.5, symmetric=True)
    clg = CLG(lat, {"c": Beam("a", (1, 0, 0, "a"), material="f")}, "c", {"f": Material(FieldSolid(fld, 0.1))})
    comp = compiled(clg)
    rng = np.random.default_rng(1)
    p = rng.uniform([-0.6, -0.6, -0.6], [2.6, 1.7, 0.6], (5000, 3))
    a, b = np.array([0, 0, 0.0]), np.array([1.0, 0, 0])
    ref = np.zeros(len(p), bool)
    for i in range(3):  # every chunk copy, the last one's beam reaching the node beyond the count
        for j in range(2):
            o = np.array([i * 1.0, j * 1.1, 0])
            t = np.clip((p - o - a) @ (b - a), 0, 1)  # a cylinder of radius 0.45 with round ends
            ref |= np.linalg.norm(p - o - t[:, None] * (b - a), axis=1) <= 0.45
    ref &= series(fld, p / 0.5) <= 0.1
    assert np.array_equal(comp.pmc(p), ref)
    # |value| never exceeds the distance to the boundary: a ball of that radius keeps p's side
    v = comp.value(p[:300])
    for q, d in zip(p[:300], v):
        s = q + np.abs(d) * 0.999 * rng.uniform(-1, 1, (64, 3)) / np.sqrt(3)
        assert np.all(comp.pmc(s) == (d <= 0))


def test_inline_data_round_trips_and_bad_data_is_named(octahedron, tmp_path):
    clg = CLG(pattern(), {"c": Ball("a", material="octa")}, "c", {"octa": Material(FieldSolid(octahedron), "beam")})
    data = json.loads(json.dumps(clg_to_dict(clg)))
    assert set(data["materials"]["octa"]["replace"]) == {"fourier"}
    back = clg_from_dict(data)
    p = np.random.default_rng(2).uniform(-0.6, 2.6, (3000, 3))
    assert np.array_equal(compiled(back).pmc(p), compiled(clg).pmc(p))
    fourier = data["materials"]["octa"]["replace"]["fourier"]
    for key, value, words in (("coeffs", fourier["coeffs"][:-1], "coefficients for"),
                              ("freqs", [[0.5, 0, 0]] * len(fourier["freqs"]), "integer triples"),
                              ("n", 0, "order"), ("level", "x", "number"), ("cell", -1, "positive"),
                              ("extra", 1, "unknown field")):
        bad = json.loads(json.dumps(data))
        bad["materials"]["octa"]["replace"]["fourier"][key] = value
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(bad))
        with pytest.raises(PleError, match=words):
            clg_from_dict(bad)
        assert main(["clg", "info", str(path)]) == 2


def test_ple_fit_writes_the_inline_field(tmp_path, octahedron):
    import trimesh
    mesh = tmp_path / "octa.stl"
    trimesh.Trimesh(OCTA_V, OCTA_F).export(mesh)
    out = tmp_path / "octa.json"
    assert main(["fit", str(mesh), "--orders", "8", "--bound", "0.05", "--out", str(out)]) == 0
    solid = clg_from_dict({"format": "ple-clg/1", "pattern": {"format": "ple-lattice/1",
                           "nodes": [{"center": [0, 0, 0], "radius": 0.5}]},
                           "chunks": {"c": {"ball": {"node": [0, 0, 0, 0], "material": "m"}}}, "solid": "c",
                           "materials": {"m": {"frame": "beam", "replace": json.loads(out.read_text())}}})
    p = np.random.default_rng(3).uniform(-0.5, 0.5, (4000, 3))
    ref = (np.linalg.norm(p, axis=1) <= 0.5) & (series(octahedron, p / 0.5) <= 0)
    assert np.array_equal(compiled(solid).pmc(p), ref)
    assert field_to_dict(FieldSolid(octahedron))["fourier"]["symmetric"] is True


def test_a_field_material_is_not_meshed_by_manifold3d(octahedron):
    from ple.meshing.clg import mesh_clg
    clg = CLG(pattern(), {"c": Ball("a", material="octa")}, "c", {"octa": Material(FieldSolid(octahedron), "beam")})
    with pytest.raises(PleError, match="voxel"):
        mesh_clg(clg)
