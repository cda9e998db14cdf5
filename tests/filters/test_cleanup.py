"""Cleanup of trimmed lattices against an independent reference: a queue-based peeling of the
beam graph (one ball at a time) and networkx components."""

from __future__ import annotations

import json
from collections import deque

import networkx as nx
import numpy as np
import pytest
import trimesh
from lattices import KINDS, random_lattice
from ple.algebra.similarity import Translation
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.body import BodyFilter
from ple.filters.cleanup import cleanup, cleanup_evaluation, skin_anchored
from ple.io.bodyfile import body_from_trimesh
from ple.io.irfile import save_ir
from ple.model.lattice import Evaluation


def reference(ev: Evaluation, anchored=None):
    """Kept rows, dangling count and component count by peeling with a queue, then networkx;
    ``anchored`` balls (held by a skin) are never peeled and join through one extra vertex."""
    n = len(ev.node_index)
    anchored = [False] * n if anchored is None else list(anchored)
    adj = [[] for _ in range(n)]
    for b, (x, y) in enumerate(ev.beam_nodes):
        adj[x].append((y, b))
        adj[y].append((x, b))
    deg = [len(a) for a in adj]
    alive, beam_alive = [True] * n, [True] * len(ev.beam_nodes)
    todo = deque(v for v in range(n) if deg[v] <= 1)
    while todo:
        v = todo.popleft()
        if not alive[v] or anchored[v]:
            continue
        alive[v] = False
        for w, b in adj[v]:
            if beam_alive[b]:
                beam_alive[b] = False
                deg[w] -= 1
                if alive[w] and deg[w] <= 1:
                    todo.append(w)
    g = nx.MultiGraph()
    g.add_nodes_from(v for v in range(n) if alive[v])
    g.add_edges_from((int(x), int(y)) for b, (x, y) in enumerate(ev.beam_nodes) if beam_alive[b])
    g.add_edges_from((v, "skin") for v in range(n) if alive[v] and anchored[v])
    comps = [c - {"skin"} for c in nx.connected_components(g)]
    comps = sorted(comps, key=lambda c: (-len(c), min(c)))
    keep = sorted(comps[0]) if comps else []
    return np.array(keep, dtype=np.int64), n - sum(alive), len(comps)


def trimmed_lattices():
    rng = np.random.default_rng(7)
    for n in range(4):
        lat = random_lattice(rng, [KINDS[(n + a) % 5] for a in range(3)], (8, 7, 6), 0.45, 0.08, nodes=2)
        mesh = trimesh.creation.torus(1.1, 0.45, major_sections=20, minor_sections=10)
        mesh.apply_transform(trimesh.transformations.random_rotation_matrix(rng.random(3)))
        lat.set_placement(Translation(-lat.evaluate().center.mean(axis=0)))
        yield lat.with_filter(BodyFilter(body_from_trimesh(mesh), ["inside", "any"][n % 2]))


@pytest.mark.parametrize("lat", list(trimmed_lattices()))
def test_cleanup_matches_peeling_and_components(lat):
    ev = lat.evaluate()
    keep, dangling, comps = reference(ev)
    out, report = cleanup_evaluation(ev)
    assert report.dangling_nodes == dangling > 0  # trimming left dangling balls: the test can fail
    assert report.components == comps
    np.testing.assert_array_equal(out.node_index, ev.node_index[keep])
    # every kept ball has degree >= 2 within the kept beams, and the kept graph is connected
    deg = np.bincount(out.beam_nodes.reshape(-1), minlength=len(out.node_index))
    assert len(out.node_index) == 0 or deg.min() >= 2
    g = nx.MultiGraph(list(map(tuple, out.beam_nodes)))
    assert len(out.node_index) == 0 or nx.number_connected_components(g) == 1
    # counts add up
    assert report.nodes + report.dangling_nodes + report.dropped_nodes == len(ev.node_index)
    assert report.beams + report.dangling_beams + report.dropped_beams == len(ev.beam_nodes)
    # as a filter of the lattice: the one evaluation gives the same nodes and beams
    cleaned, _ = cleanup(lat)
    again = cleaned.evaluate()
    np.testing.assert_array_equal(again.node_index, out.node_index)
    np.testing.assert_array_equal(again.beam_nodes, out.beam_nodes)


def test_cleanup_flag(tmp_path, capsys):
    lat = next(trimmed_lattices())
    mesh = trimesh.creation.torus(1.1, 0.45, major_sections=20, minor_sections=10)
    mesh_path = tmp_path / "t.obj"
    mesh.export(mesh_path)
    ir = tmp_path / "l.json"
    save_ir(lat.unfiltered(), ir)
    out = tmp_path / "e.npz"
    assert main(["eval", str(ir), "--body", str(mesh_path), "--fill", "any", "--cleanup", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "cleanup: removed" in err and "kept" in err
    want, report = cleanup_evaluation(lat.unfiltered().with_filter(
        BodyFilter(body_from_trimesh(mesh), "any")).evaluate())
    assert f"kept {report.nodes:,} balls" in err
    with np.load(out) as got:
        np.testing.assert_array_equal(got["node_index"], want.node_index)


def anchored_by_brute_force(mesh, center, radius, thickness):
    """Balls reaching into the skin: trimesh's containment and closest points over every face."""
    inside = mesh.contains(center)
    _, dist, _ = trimesh.proximity.closest_point(mesh, center)
    return np.where(inside, dist < radius + thickness, dist < radius)


@pytest.mark.parametrize("n", range(4))
def test_cleanup_keeps_beams_ending_on_the_skin(n):
    lat = list(trimmed_lattices())[n]
    body = lat.filter.body
    mesh = trimesh.Trimesh(body.vertices, body.faces)
    ev = lat.evaluate()
    held = anchored_by_brute_force(mesh, ev.center, ev.radius, 0.12)
    np.testing.assert_array_equal(skin_anchored(body, 0.12, ev.center, ev.radius), held)
    keep, dangling, comps = reference(ev, held)
    out, report = cleanup_evaluation(ev, anchored=held)
    np.testing.assert_array_equal(out.node_index, ev.node_index[keep])
    assert report.dangling_nodes == dangling and report.components == comps
    assert 0 < report.anchored and report.nodes > cleanup_evaluation(ev)[1].nodes  # the skin held balls
    cleaned, rep = cleanup(lat, skin=0.12)  # the lattice's own body, as the filter of the one evaluation
    np.testing.assert_array_equal(cleaned.evaluate().node_index, out.node_index)
    assert rep == report


def test_cleanup_skin_flag(tmp_path, capsys):
    lat = next(trimmed_lattices())
    mesh = trimesh.Trimesh(lat.filter.body.vertices, lat.filter.body.faces)
    mesh_path = tmp_path / "t.stl"
    mesh.export(mesh_path)
    ir = tmp_path / "l.json"
    save_ir(lat.unfiltered(), ir)
    out = tmp_path / "e.npz"
    assert main(["eval", str(ir), "--body", str(mesh_path), "--cleanup", "--skin", "0.12", "--out", str(out)]) == 0
    assert "held by the skin" in capsys.readouterr().err
    want, _ = cleanup(lat, skin=0.12)
    with np.load(out) as got:
        np.testing.assert_array_equal(got["node_index"], want.evaluate().node_index)
    assert main(["eval", str(ir), "--cleanup", "--skin", "0.12", "--out", str(out)]) == 2
    assert "--skin needs a body" in capsys.readouterr().err


def test_cleanup_is_data_in_the_ir(tmp_path, capsys):
    from ple.filters.ir import lattice_from_ir
    from ple.io.bodyfile import load_body
    from ple.io.irfile import load_ir

    lat = list(trimmed_lattices())[1]  # an `any` fill
    mesh = trimesh.Trimesh(lat.filter.body.vertices, lat.filter.body.faces)
    mesh.export(tmp_path / "t.stl")
    body = load_body(tmp_path / "t.stl")
    lat = lat.unfiltered().with_filter(BodyFilter(body, "any"))
    ev = lat.evaluate()
    keep, _, _ = reference(ev, anchored_by_brute_force(mesh, ev.center, ev.radius, 0.12))
    cleaned, _ = cleanup(lat, skin=0.12)
    save_ir(cleaned, tmp_path / "c.json")
    data = json.loads((tmp_path / "c.json").read_text())
    assert data["filter"] == {"cleanup": {"filter": {"body": {"mesh": "t.stl", "mode": "any"}}, "largest": True,
                                          "skin": 0.12}}
    back = load_ir(tmp_path / "c.json")
    np.testing.assert_array_equal(back.evaluate().node_index, ev.node_index[keep])
    ir = tmp_path / "l.json"
    save_ir(lat.unfiltered(), ir)
    out = tmp_path / "cli.json"
    assert main(["ir", str(ir), "--body", str(tmp_path / "t.stl"), "--fill", "any", "--cleanup", "--skin", "0.12",
                 "--out", str(out)]) == 0
    np.testing.assert_array_equal(load_ir(out).evaluate().node_index, ev.node_index[keep])
    base = {"format": "ple-lattice/1", "nodes": [{"center": [0, 0, 0], "radius": 0.1}]}
    for bad, message in (({"largest": 1}, "filter.cleanup.largest: expected true or false"),
                         ({"skin": -1}, "filter.cleanup.skin: must be positive"),
                         ({"keep": 1}, "filter.cleanup.keep: unknown field"),
                         ({"filter": {"stencil": {}}}, "filter.cleanup.filter.stencil.")):
        with pytest.raises(PleError) as err:
            lattice_from_ir({**base, "filter": {"cleanup": bad}})
        assert str(err.value).startswith(message), str(err.value)
