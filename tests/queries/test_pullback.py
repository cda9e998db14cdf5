"""Nodes-only BIQ (``beams=False``, ``ple biq --nodes-only``) and the pulled-back query
(``ple.queries.pullback``): hit sets equal an independent brute force (every element evaluated,
then distance tests) on random, curved and warped lattices, with and without a placement."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from ple.algebra.similarity import Swirl
from ple.bench.curved import curved_lattice
from ple.cli.main import main
from ple.program.sources import load_lattice
from ple.queries import biq, pullback, rangefinder
from ple.queries.hits import _unique_rows, split_hits
from ple.queries.rangefinder import cached_plan
from test_biq import KINDS, brute_force, lattice_of, random_lattice, random_queries

TOL = 1e-9  # brute-force distances within this of the query radius are not asserted either way


def near_node_queries(rng, lat, q, scale):
    """Balls at random nodes plus noise, radii ``scale`` times the node's radius."""
    idx = np.stack([rng.integers(0, n, q) for n in lat.counts] + [rng.integers(0, len(lat.nodes), q)], axis=1)
    c, r = lat.node_balls(idx)
    return c + rng.normal(size=(q, 3)) * r[:, None], scale * r


def assert_nodes_match_brute_force(lat, c, r):
    d_nodes, _, ev = brute_force(lat, c, r)
    res = biq.query(lat, c, r, beams=False)
    for t, x in enumerate(res):
        assert x.beams.shape == (0, 4)
        got = {tuple(v) for v in x.nodes}
        sure = {tuple(v) for v in ev.node_index[d_nodes[t] <= r[t] - TOL]}
        maybe = {tuple(v) for v in ev.node_index[d_nodes[t] <= r[t] + TOL]}
        assert sure <= got <= maybe
    return res


def assert_beams_match_brute_force(lat, c, r):
    _, d_beams, ev = brute_force(lat, c, r)
    res = biq.query(lat, c, r)
    for t, x in enumerate(res):
        got = {tuple(v) for v in x.beams}
        sure = {tuple(v) for v in ev.beam_index[d_beams[t] <= r[t] - TOL]}
        maybe = {tuple(v) for v in ev.beam_index[d_beams[t] <= r[t] + TOL]}
        assert sure <= got <= maybe
    return res


@pytest.mark.parametrize("kinds", [(k, k, k) for k in KINDS] + [
    ("translation", "rotation", "swirl"), ("rotation", "screw", "scaling"), ("screw", "swirl", "rotation")])
def test_nodes_only_equals_brute_force_random(kinds):
    rng = np.random.default_rng(abs(hash(kinds)) % 2**32)
    for _ in range(3):
        lat = random_lattice(rng, kinds, counts=(4, 5, 6))
        for scale in (1.0, 4.0):
            c, r = random_queries(rng, lat, 40, scale)
            res = assert_nodes_match_brute_force(lat, c, r)
            assert {x.path for x in res} == {"pullback"}


@pytest.mark.parametrize("placed", [False, True])
def test_nodes_only_curved_and_warped(placed):
    rng = np.random.default_rng(3)
    for lat in (curved_lattice(9), load_lattice("thesis_warped", {"n": 9}), lattice_of("wrap-swirl")):
        if placed:
            lat.set_placement(Swirl(0.4, [1, 0.5, 0], [2, 0, 1], 1.7))
        for c, r in (random_queries(rng, lat, 60, 2.0), near_node_queries(rng, lat, 60, 3.0)):
            assert_nodes_match_brute_force(lat, c, r)


def test_nodes_only_equals_the_nodes_of_a_full_query():
    rng = np.random.default_rng(4)
    for case in ("1", "u", "wrap"):
        lat = lattice_of(case)
        c, r = random_queries(rng, lat, 50, 3.0)
        full, nodes = biq.query(lat, c, r), biq.query(lat, c, r, beams=False)
        assert all(np.array_equal(a.nodes, b.nodes) for a, b in zip(full, nodes))
        naive = biq.query(lat, c, r, "naive", beams=False)
        assert all(np.array_equal(a.nodes, b.nodes) and len(b.beams) == 0 for a, b in zip(full, naive))


def test_pullback_beams_equal_brute_force_on_the_general_case():
    """Nodes and beams of a lattice whose U, V, W do not commute come from the pulled-back query."""
    rng = np.random.default_rng(5)
    for lat in (curved_lattice(8), load_lattice("thesis_warped", {"n": 8}), lattice_of("wrap")):
        assert cached_plan(lat).path == "uv" and pullback.fits(lat)
        for c, r in (random_queries(rng, lat, 60, 2.0), near_node_queries(rng, lat, 60, 3.0)):
            res = assert_beams_match_brute_force(lat, c, r)
            assert {x.path for x in res} == {"pullback"}


def test_slab_too_large_for_the_plan_falls_back(monkeypatch):
    monkeypatch.setattr(pullback, "MAX_SLAB_BALLS", 10)
    lat = curved_lattice(6)
    assert not pullback.fits(lat)
    rng = np.random.default_rng(6)
    c, r = random_queries(rng, lat, 30, 3.0)
    res = assert_nodes_match_brute_force(lat, c, r)
    assert {x.path for x in res} == {"uv"}


def test_clearance_is_a_lower_bound():
    rng = np.random.default_rng(11)
    pts = rng.normal(size=(300, 3)) * [5, 2, 0.3]
    clear = pullback._Clearance.of(pts)
    y = rng.normal(size=(2000, 3)) * 8
    nearest = np.linalg.norm(y[:, None] - pts[None], axis=2).min(axis=1)
    assert np.all(clear.lower_bound(y) <= nearest + 1e-12)


def test_cli_nodes_only(tmp_path, capsys):
    lat = curved_lattice(6)
    rng = np.random.default_rng(12)
    c, r = near_node_queries(rng, lat, 20, 3.0)
    q = tmp_path / "q.npy"
    np.save(q, np.concatenate([c, r[:, None]], axis=1))
    prog = tmp_path / "curved.py"
    prog.write_text("from ple.bench.curved import curved_lattice\n\ndef lattice():\n    return curved_lattice(6)\n")
    out = tmp_path / "h.json"
    assert main(["biq", str(prog), "--queries", str(q), "--out", str(out), "--nodes-only"]) == 0
    doc = json.loads(out.read_text())
    want = biq.query(lat, c, r, beams=False)
    assert [set(x) for x in doc["queries"]] == [{"nodes"}] * len(want)
    assert [x["nodes"] for x in doc["queries"]] == [w.nodes.tolist() for w in want]
    assert sum(len(x["nodes"]) for x in doc["queries"]) > 0
    out_full = tmp_path / "full.json"
    assert main(["biq", str(prog), "--queries", str(q), "--out", str(out_full)]) == 0
    assert [x["nodes"] for x in json.loads(out_full.read_text())["queries"]] == [x["nodes"] for x in doc["queries"]]
    counts = tmp_path / "c.json"
    assert main(["biq", str(prog), "--queries", str(q), "--out", str(counts), "--nodes-only", "--count"]) == 0
    assert json.loads(counts.read_text())["queries"] == [{"nodes": len(w.nodes)} for w in want]


def test_unique_rows_is_numpys_unique():
    rng = np.random.default_rng(13)
    for n in (0, 1, 2, 40, 3000):
        a = rng.integers(-2, 3, (n, 5))
        assert np.array_equal(_unique_rows(a), np.unique(a, axis=0).reshape(-1, 5))


compiled = pytest.mark.skipif(rangefinder._compiled is None, reason="the compiled pulled-back query is not built")


def numpy_form(lat, c, r, beams):
    return split_hits(len(c), *pullback._query_numpy(lat, c, r, beams), "pullback")


@compiled
@pytest.mark.parametrize("beams", [False, True])
def test_compiled_form_equals_the_numpy_form(beams):
    """Bit for bit: the same rows, in the same order, with the same per-query ends, on random
    steady lattices of every kind, curved and warped ones, placed or not, at many query sizes."""
    rng = np.random.default_rng(21 + beams)
    lats = [random_lattice(rng, kinds, counts=(4, 5, 6)) for kinds in
            [(k, k, k) for k in KINDS] + [("screw", "swirl", "rotation"), ("swirl", "translation", "scaling")]]
    lats += [curved_lattice(9), load_lattice("thesis_warped", {"n": 9}), lattice_of("wrap-swirl")]
    placed = curved_lattice(7)
    placed.set_placement(Swirl(0.4, [1, 0.5, 0], [2, 0, 1], 1.7))
    for lat in [*lats, placed]:
        assert pullback.fits(lat) and pullback.cached_pullback(lat).kernel is not None
        for c, r in (random_queries(rng, lat, 50, 0.5), random_queries(rng, lat, 50, 4.0),
                     near_node_queries(rng, lat, 50, 3.0), (np.zeros((0, 3)), np.zeros(0))):
            got, want = pullback.query(lat, c, r, beams), numpy_form(lat, c, r, beams)
            for name in ("nodes", "node_ends", "beams", "beam_ends"):
                assert np.array_equal(getattr(got, name), getattr(want, name)), name
            assert beams or len(got.beams) == 0


@compiled
def test_compiled_form_equals_brute_force_on_warped_lattices():
    rng = np.random.default_rng(22)
    for lat in (load_lattice("thesis_warped", {"n": 10}), curved_lattice(10)):
        for c, r in (random_queries(rng, lat, 80, 2.0), near_node_queries(rng, lat, 80, 3.0)):
            assert_nodes_match_brute_force(lat, c, r)
            assert_beams_match_brute_force(lat, c, r)


def test_the_numpy_form_answers_when_the_compiled_one_is_absent(monkeypatch):
    lat = load_lattice("thesis_warped", {"n": 8})
    rng = np.random.default_rng(23)
    c, r = near_node_queries(rng, lat, 40, 3.0)
    monkeypatch.setattr(rangefinder, "_compiled", None)
    assert pullback.cached_pullback(lat).kernel is None
    assert_beams_match_brute_force(lat, c, r)


def test_results_are_a_sequence_of_per_query_views():
    lat = curved_lattice(6)
    rng = np.random.default_rng(24)
    c, r = near_node_queries(rng, lat, 25, 3.0)
    res = biq.query(lat, c, r)
    listed = list(res)
    assert len(res) == len(listed) == 25
    for t in range(-25, 25):
        assert np.array_equal(res[t].nodes, listed[t].nodes) and np.array_equal(res[t].beams, listed[t].beams)
    assert [x.nodes.tolist() for x in res[3:9:2]] == [x.nodes.tolist() for x in listed[3:9:2]]
    assert sum(len(x.nodes) for x in res) == len(res.nodes)
    with pytest.raises(IndexError):
        res[25]


def test_kdtree_bench_row_finds_the_trees_hits(monkeypatch):
    """``ple bench biq``'s KD-tree comparison: PLE (nodes only, nodes and beams) and the prebuilt
    cKDTree with its exact tests give the same hits, on a small warped lattice."""
    from ple.bench import biq as bench_biq

    monkeypatch.setattr(bench_biq, "load_lattice", lambda name: load_lattice(name, {"n": 12}))
    row = bench_biq.kdtree_row(argparse.Namespace(tree_lattice="thesis_warped", tree_queries=300, repeat=1, seed=5))
    assert row["nodes_only"]["same_hits"] and row["nodes_and_beams"]["same_hits"]
    assert row["node_hits"] > 0 and row["beam_hits"] > 0 and row["path"] == "pullback"
