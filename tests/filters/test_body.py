"""Body filters: kept sets against an independent inside test (trimesh ray containment with an
R-tree, and brute-force point-triangle distances over every face), every fill mode, on random
lattices and bodies; bad bodies are named."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from lattices import KINDS, random_lattice
from ple.algebra.similarity import Rotation, Scaling, Similarity, Translation
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.body import Body, BodyFilter
from ple.filters.ir import lattice_to_ir
from ple.io.bodyfile import body_from_trimesh, load_body
from ple.io.irfile import load_ir, save_ir
from ple.model.lattice import Lattice

AMBIGUOUS = 1e-7  # truth within this of a decision threshold is not asserted (the tests differ there)


# ----- independent truth ---------------------------------------------------------------------------
def true_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest of all faces (trimesh's exact per-triangle closest point)."""
    tri = mesh.triangles
    out = np.empty(len(points))
    for n, p in enumerate(points):
        q = trimesh.triangles.closest_point(tri, np.repeat(p[None], len(tri), axis=0))
        out[n] = np.linalg.norm(q - p, axis=1).min()
    return out


def truth(mesh, lat: Lattice, mode: str):
    """(kept, certain): the kept nodes of the whole lattice by an independent test, and where the
    truth is far enough from a threshold to be asserted."""
    ev = lat.unfiltered().evaluate()
    c, r = ev.center, ev.radius
    if mode == "centroid":
        tc = lat.template_centers.mean(axis=0)
        nn = len(lat.nodes)
        groups = ev.node_index[::nn, :3]
        m = lat.group_matrices(groups[:, 0], groups[:, 1], groups[:, 2])
        g = np.einsum("nab,b->na", m[:, :3, :3], tc) + m[:, :3, 3]
        inside = mesh.contains(g)
        d = true_distance(mesh, g)
        return np.repeat(inside, nn), np.repeat(d > AMBIGUOUS, nn)
    inside = mesh.contains(c)
    d = true_distance(mesh, c)
    if mode == "inside":
        kept = inside & (d >= r)
    else:
        kept = inside | (d < r)
    return kept, np.abs(d - r) > AMBIGUOUS


def wavy_sphere(rng, subdivisions=3):
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    d = m.vertices / np.linalg.norm(m.vertices, axis=1)[:, None]
    bumps = 1 + 0.25 * np.sin(3 * d[:, 0] + rng.uniform(0, 6)) * np.cos(2 * d[:, 1] + rng.uniform(0, 6))
    return trimesh.Trimesh(m.vertices * bumps[:, None], m.faces)


def bodies(rng):
    """Random bodies: a wavy sphere, a rotated box, a torus (a hole through it), a non-convex union."""
    box = trimesh.creation.box(extents=rng.uniform(1.2, 2.4, 3))
    box.apply_transform(trimesh.transformations.random_rotation_matrix(rng.random(3)))
    torus = trimesh.creation.torus(1.2, 0.5, major_sections=24, minor_sections=12)
    a = trimesh.creation.box(extents=(2.4, 0.8, 0.8))
    b = trimesh.creation.box(extents=(0.8, 2.4, 0.8))
    b.apply_translation((0.6, 0.3, 0.2))
    union = trimesh.boolean.union([a, b], engine="manifold")
    return {"wavy": wavy_sphere(rng), "box": box, "torus": torus, "union": union}


@pytest.fixture(scope="module")
def cases():
    rng = np.random.default_rng(19)
    out = []
    for n, (name, mesh) in enumerate(bodies(rng).items()):
        lat = random_lattice(rng, [KINDS[(n + a) % len(KINDS)] for a in range(3)], (7, 6, 5), 0.45, 0.09, nodes=2)
        shift = mesh.bounds.mean(axis=0) - lat.evaluate().center.mean(axis=0)
        lat.set_placement(Translation(shift))
        out.append((name, mesh, lat))
    return out


@pytest.mark.parametrize("mode", ["inside", "centroid", "any"])
def test_kept_sets_equal_the_independent_inside_test(cases, mode):
    for name, mesh, lat in cases:
        body = body_from_trimesh(mesh)
        kept, certain = truth(mesh, lat, mode)
        got = lat.with_filter(BodyFilter(body, mode))
        ev = got.evaluate()
        mine = np.zeros(lat.node_count(), dtype=bool)
        nn, (_, nv, nw) = len(lat.nodes), lat.counts
        rows = ((ev.node_index[:, 0] * nv + ev.node_index[:, 1]) * nw + ev.node_index[:, 2]) * nn + ev.node_index[:, 3]
        mine[rows] = True
        assert certain.mean() > 0.99, name
        assert 0 < kept.sum() < len(kept), (name, mode)  # the body cuts the lattice: the test can fail
        np.testing.assert_array_equal(mine[certain], kept[certain], err_msg=f"{name} {mode}")
        # beams: exactly those of the bare program with both ends kept
        full = lat.unfiltered().evaluate()
        alive = mine[full.beam_nodes[:, 0]] & mine[full.beam_nodes[:, 1]]
        if certain.all():
            assert len(ev.beam_nodes) == alive.sum()


def test_inside_test_is_exact_on_rays_through_vertices_and_edges():
    """Points whose vertical rays pass exactly through the vertices and edges of a triangulated,
    subdivided box (the worst case of ray parity) against the box's own inequalities."""
    box = trimesh.creation.box(extents=(2, 2, 2)).subdivide().subdivide()
    body = body_from_trimesh(box)
    g = np.linspace(-1.25, 1.25, 11)  # hits x, y = ±1, ±0.5, 0 exactly: vertex and edge lines
    p = np.stack(np.meshgrid(g, g, np.linspace(-1.3, 1.3, 7), indexing="ij"), axis=-1).reshape(-1, 3)
    p = p[np.abs(np.abs(p[:, 2]) - 1) > 1e-9]
    inside = np.all(np.abs(p) < 1 - 1e-12, axis=1)
    on_side = np.any(np.isclose(np.abs(p[:, :2]), 1.0), axis=1)  # on a side wall: either answer
    np.testing.assert_array_equal(body.contains(p)[~on_side], inside[~on_side])


def test_distances_are_exact(cases):
    rng = np.random.default_rng(3)
    _, mesh, _ = cases[0]
    body = body_from_trimesh(mesh)
    p = rng.uniform(mesh.bounds[0] - 0.3, mesh.bounds[1] + 0.3, (300, 3))
    d = true_distance(mesh, p)
    np.testing.assert_allclose(body.distance(p, 0.4), np.minimum(d, 0.4), rtol=0, atol=1e-12)
    r = rng.uniform(0.01, 0.3, len(p))
    np.testing.assert_array_equal(body.near(p, r), d < r)


def test_placement_moves_the_body(cases):
    _, mesh, lat = cases[0]
    place = Translation((0.2, -0.1, 0.3)) @ Rotation(0.7, (1, 2, 3), (0, 0, 0)) @ Scaling(1.1, (0, 0, 0))
    moved = mesh.copy()
    moved.apply_transform(place.matrix)
    a = lat.with_filter(BodyFilter(body_from_trimesh(mesh, place), "any")).evaluate()
    kept, certain = truth(moved, lat, "any")
    assert certain.all()
    assert len(a.node_index) == kept.sum()


def test_open_mesh_winding_fallback_agrees_away_from_the_hole():
    rng = np.random.default_rng(5)
    mesh = wavy_sphere(rng, 2)
    holed = trimesh.Trimesh(mesh.vertices, mesh.faces[1:], process=False)
    with pytest.raises(PleError, match="not closed"):
        body_from_trimesh(holed)
    body = body_from_trimesh(holed, open="winding")
    p = rng.uniform(-1.4, 1.4, (2000, 3))
    far = np.linalg.norm(p - mesh.triangles[0].mean(axis=0), axis=1) > 0.4
    np.testing.assert_array_equal(body.contains(p)[far], mesh.contains(p)[far])


def test_inward_faces_are_flipped_and_stl_corners_merged(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=2)
    inverted = trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False)
    path = tmp_path / "inv.stl"
    inverted.export(path)
    body = load_body(path)
    p = np.random.default_rng(1).uniform(-1.2, 1.2, (500, 3))
    np.testing.assert_array_equal(body.contains(p), mesh.contains(p))
    assert body.volume == pytest.approx(mesh.volume, rel=1e-6)


# ----- bad bodies ----------------------------------------------------------------------------------
def write_bad(tmp_path, kind):
    box = trimesh.creation.box()
    path = tmp_path / f"{kind}.obj"
    if kind == "open":
        trimesh.Trimesh(box.vertices, box.faces[:-1], process=False).export(path)
    elif kind == "empty":
        path.write_text("# nothing\n")
    elif kind == "nan":
        v = box.vertices.copy()
        v[3, 1] = np.nan
        path.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v)
                        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in box.faces))
    elif kind == "missing":
        pass
    elif kind == "flat":
        trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2], [0, 2, 1]], process=False).export(path)
    return path


@pytest.mark.parametrize("kind, message", [("open", "not closed: 3 edges"), ("empty", "empty"),
                                           ("nan", "1 of 8 vertices are NaN"), ("missing", "no such file"),
                                           ("flat", "encloses no volume")])
def test_bad_bodies_exit_2_naming_the_problem(tmp_path, capsys, kind, message):
    path = write_bad(tmp_path, kind)
    assert main(["info", "cubic", "--body", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and str(path) in err, err


def test_bad_body_arrays():
    box = trimesh.creation.box()
    with pytest.raises(PleError, match="empty"):
        Body(np.zeros((0, 3)), np.zeros((0, 3), int))
    with pytest.raises(PleError, match="face indices"):
        Body(box.vertices, box.faces + 1)
    with pytest.raises(PleError, match="fill mode"):
        BodyFilter(body_from_trimesh(box), "outside")


# ----- ple-lattice/1 and the CLI ----------------------------------------------------------------------
def test_ir_body_is_relative_to_the_json_file_and_round_trips(tmp_path, cases):
    _, mesh, lat = cases[0]
    (tmp_path / "parts").mkdir()
    mesh_path = tmp_path / "parts" / "part.stl"
    mesh.export(mesh_path)
    filtered = lat.with_filter(BodyFilter(load_body(mesh_path), "centroid"))
    out = tmp_path / "lat.json"
    save_ir(filtered, out)
    data = json.loads(out.read_text())
    assert data["filter"] == {"body": {"mesh": "parts/part.stl", "mode": "centroid"}}
    back = load_ir(out)
    a, b = filtered.evaluate(), back.evaluate()
    np.testing.assert_array_equal(a.node_index, b.node_index)
    np.testing.assert_array_equal(a.beam_index, b.beam_index)
    # the path is resolved against the JSON file, not the working directory; a missing mesh is refused
    data["filter"]["body"]["mesh"] = "parts/nope.stl"
    out.write_text(json.dumps(data))
    with pytest.raises(PleError, match=r"filter\.body\.mesh 'parts/nope.stl': no such file \(expected a body mesh"):
        load_ir(out)
    data["filter"]["body"]["mode"] = "half"
    out.write_text(json.dumps(data))
    with pytest.raises(PleError, match=r"filter\.body\.mode: expected one of inside, centroid, any"):
        load_ir(out)
    with pytest.raises(PleError, match="as arrays cannot be written"):
        lattice_to_ir(lat.with_filter(BodyFilter(body_from_trimesh(mesh))))


def test_cli_body_flags_match_the_api(tmp_path, cases, capsys):
    _, mesh, lat = cases[1]
    ir = tmp_path / "lat.json"
    save_ir(lat, ir)
    mesh_path = tmp_path / "box.ply"
    mesh.export(mesh_path)
    out = tmp_path / "e.npz"
    assert main(["eval", str(ir), "--body", str(mesh_path), "--fill", "any", "--out", str(out)]) == 0
    want = lat.with_filter(BodyFilter(body_from_trimesh(mesh), "any")).evaluate()
    with np.load(out) as got:
        np.testing.assert_array_equal(got["node_index"], want.node_index)
        np.testing.assert_array_equal(got["beam_nodes"], want.beam_nodes)
    assert isinstance(Similarity(), Similarity)
