"""BIQ, any_hit, PMC and distance queries: RangeFinder hit sets equal brute force (naive
exact tests of every element) on random lattices of every similarity kind."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple.algebra.elements import beam_distance
from ple.algebra.similarity import Rotation, Scaling, Screw, Similarity, Swirl, Translation
from ple.cli.main import main
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice
from ple.queries import biq, rangefinder
from ple.queries.hits import _unique_rows, split_hits
from ple.queries.rangefinder import cached_plan, row_candidates

KINDS = ("translation", "rotation", "scaling", "screw", "swirl")


def random_similarity(rng, kind: str) -> Similarity:
    axis, point = rng.normal(size=3), rng.normal(size=3) * 2
    angle = rng.uniform(0.1, 0.9) * rng.choice([-1, 1])
    factor = rng.uniform(0.85, 1.15)
    return {"translation": lambda: Translation(rng.normal(size=3)),
            "rotation": lambda: Rotation(angle, axis, point),
            "scaling": lambda: Scaling(factor, point),
            "screw": lambda: Screw(angle, axis, point, rng.normal()),
            "swirl": lambda: Swirl(angle, axis, point, factor)}[kind]()


def random_lattice(rng, kinds, counts=(3, 4, 5)) -> Lattice:
    lat = Lattice()
    nn = int(rng.integers(1, 3))
    for _ in range(nn):
        lat.add_node(rng.normal(size=3) * 0.5, rng.uniform(0.1, 0.3))
    for _ in range(int(rng.integers(1, 5))):
        off = rng.integers(-1, 2, 3)
        a, b = (int(x) for x in rng.integers(0, nn, 2))
        if a == b and not off.any():
            off[0] = 1
        lat.add_beam(a, b, *(int(x) for x in off))
    lat.set_u(counts[0], random_similarity(rng, kinds[0]))
    lat.set_v(counts[1], random_similarity(rng, kinds[1]))
    lat.set_w(counts[2], random_similarity(rng, kinds[2]))
    return lat


def random_queries(rng, lat, q=30, scale=3.0):
    lo, hi = lat.bounds()
    return rng.uniform(lo, hi, (q, 3)), rng.uniform(0, 1, q) * lat.mean_radius() * scale


def assert_same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert np.array_equal(x.nodes, y.nodes)
        assert np.array_equal(x.beams, y.beams)


def brute_force(lat, c, r):
    """Independent reference: evaluate everything, then distance tests (no slabs, no ranges)."""
    ev = lat.evaluate()
    d_nodes = np.linalg.norm(c[:, None] - ev.center[None], axis=2) - ev.radius[None]
    a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
    d_beams = beam_distance(c[:, None], ev.center[a][None], ev.radius[a][None], ev.center[b][None], ev.radius[b][None])
    return d_nodes, d_beams, ev


@pytest.mark.parametrize("kinds", [(k, k, k) for k in KINDS] + [
    ("translation", "rotation", "translation"), ("scaling", "rotation", "swirl"), ("rotation", "screw", "scaling"),
    ("swirl", "translation", "screw"), ("screw", "swirl", "rotation")])
def test_rangefinder_equals_naive(kinds):
    rng = np.random.default_rng(abs(hash(kinds)) % 2**32)
    for _ in range(3):
        lat = random_lattice(rng, kinds)
        c, r = random_queries(rng, lat)
        assert_same(biq.query(lat, c, r, "naive"), biq.query(lat, c, r, "rangefinder"))


def test_naive_equals_independent_brute_force():
    rng = np.random.default_rng(11)
    lat = random_lattice(rng, ("swirl", "screw", "rotation"))
    c, r = random_queries(rng, lat, 20)
    d_nodes, d_beams, ev = brute_force(lat, c, r)
    res = biq.query(lat, c, r, "naive")
    for t, x in enumerate(res):
        nodes = ev.node_index[d_nodes[t] <= r[t] + 1e-12]
        beams = ev.beam_index[d_beams[t] <= r[t] + 1e-12]
        assert np.array_equal(x.nodes, nodes[np.lexsort(nodes.T[::-1])])
        assert np.array_equal(x.beams, beams[np.lexsort(beams.T[::-1])])


def lattice_of(path):
    lat = Lattice()
    a = lat.add_node([1.0, 0, 0], 0.12)
    b = lat.add_node([1.3, 0.2, 0.4], 0.08)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (0, -1, 1)]:
        lat.add_beam(a, b, *off)
    lat.add_beam(a, a, 0, 0, 1)
    if path == "1":  # skewed translations: dual-basis maps
        lat.set_u(4, Translation([1, 0.2, 0]))
        lat.set_v(5, Translation([0.3, 1, 0.1]))
        lat.set_w(4, Translation([0, 0.4, 1]))
    elif path == "1-polar":  # scaling and rotation about one fixed point: commuting, invariant maps
        lat.set_u(4, Scaling(1.2, [0, 0, 0]))
        lat.set_v(6, Rotation(0.5, [0, 0, 1], [0, 0, 0]))
    elif path == "u":  # cylindrical: radial U, angular V (wraps), axial W
        lat.set_u(3, Translation([0.6, 0, 0]))
        lat.set_v(16, Rotation(0.5, [0, 0, 1], [0, 0, 0]))
        lat.set_w(5, Translation([0, 0, 0.7]))
    elif path == "wrap":  # a W-row wrapping about its axis several times (screw)
        lat.set_u(3, Translation([0.5, 0, 0]))
        lat.set_v(2, Translation([0, 2, 0]))
        lat.set_w(40, Screw(0.7, [0, 0, 1], [0, 0, 0], 0.05))
    else:  # swirl W-rows wrapping more than once
        lat.set_u(3, Rotation(0.3, [0, 1, 0], [0, 0, 3]))
        lat.set_v(3, Translation([0, 0.8, 0]))
        lat.set_w(30, Swirl(1.3, [0, 0, 1], [0, 0, 0], 1.02))
    return lat


@pytest.mark.parametrize("case,path", [("1", "1"), ("1-polar", "1"), ("u", "u"), ("wrap", "uv"), ("wrap-swirl", "uv")])
def test_paths_detected_and_exact(case, path):
    lat = lattice_of(case)
    assert cached_plan(lat).path == path
    rng = np.random.default_rng(7)
    for scale in (1.0, 6.0):
        c, r = random_queries(rng, lat, 40, scale)
        res = biq.query(lat, c, r, "rangefinder")
        # the general case's nodes and beams come from the pulled-back query (ple.queries.pullback)
        assert {x.path for x in res} == {"pullback" if path == "uv" else path}
        assert_same(biq.query(lat, c, r, "naive"), res)


def test_placement_and_thesis_presets_small():
    lat = lattice_of("u")
    lat.set_placement(Swirl(0.7, [1, 1, 0], [0.5, 0, 2], 1.3))
    rng = np.random.default_rng(8)
    c, r = random_queries(rng, lat, 30, 4)
    assert_same(biq.query(lat, c, r, "naive"), biq.query(lat, c, r))
    for name, params in [("thesis_regular", ["n=4"]), ("thesis_cylindrical", ["nu=3", "nv=12", "nw=3"]),
                         ("thesis_warped", ["n=5"])]:
        lat = load_lattice(name, params)
        c, r = random_queries(rng, lat, 30, 2)
        assert_same(biq.query(lat, c, r, "naive"), biq.query(lat, c, r))


def test_near_tangent_queries():
    """Query balls tangent to a node or a beam, just touching or just missing it."""
    rng = np.random.default_rng(9)
    lat = lattice_of("u")
    ev = lat.evaluate()
    centers, radii = [], []
    for _ in range(60):
        p = rng.uniform(*lat.bounds())
        if rng.random() < 0.5:
            n = rng.integers(len(ev.radius))
            d = np.linalg.norm(p - ev.center[n]) - ev.radius[n]
        else:
            m = rng.integers(len(ev.beam_nodes))
            a, b = ev.beam_nodes[m]
            d = float(beam_distance(p, ev.center[a], ev.radius[a], ev.center[b], ev.radius[b]))
        if d <= 1e-3:
            continue
        for f in (1 + 1e-12, 1 - 1e-9, 1.0):
            centers.append(p)
            radii.append(d * f)
    c, r = np.array(centers), np.array(radii)
    assert_same(biq.query(lat, c, r, "naive"), biq.query(lat, c, r))


def test_any_hit_and_pmc_match_brute_force():
    rng = np.random.default_rng(10)
    for kinds in [("translation",) * 3, ("rotation", "swirl", "screw")]:
        lat = random_lattice(rng, kinds)
        c, r = random_queries(rng, lat, 200, 2)
        d_nodes, d_beams, _ = brute_force(lat, c, r)
        expect = (d_nodes <= r[:, None] + 1e-12).any(axis=1) | (d_beams <= r[:, None] + 1e-12).any(axis=1)
        assert np.array_equal(biq.any_hit(lat, c, r), expect)
        inside = (d_nodes <= 1e-12).any(axis=1) | (d_beams <= 1e-12).any(axis=1)
        assert np.array_equal(biq.pmc(lat, c), inside)


def test_distance_query():
    rng = np.random.default_rng(12)
    lat = lattice_of("wrap")
    p = rng.uniform(*lat.bounds())
    d_nodes, d_beams, _ = brute_force(lat, p[None], np.zeros(1))
    nearest = min(d_nodes.min(), d_beams.min())
    res = biq.distance_query(lat, p, max(nearest, 0) + 0.3)
    assert np.isclose(res.distance, nearest)
    far = biq.distance_query(lat, p + 1e6, 0.1)
    assert far.distance == np.inf and len(far.nodes) == 0


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(KINDS), st.integers(0, 2**31 - 1))
def test_row_range_is_conservative(kind, seed):
    """§7.1.2 theorem: every k whose ball S**k(B0) meets the query lies in the range."""
    rng = np.random.default_rng(seed)
    s = random_similarity(rng, kind)
    n = 60
    c0, r0 = rng.normal(size=3), rng.uniform(0.05, 0.4)
    mats = s.power_matrices(np.arange(n))
    centers = mats[:, :3, :3] @ c0 + mats[:, :3, 3]
    radii = r0 * s.factor ** np.arange(n)
    pick = rng.integers(n)
    qc = centers[pick] + rng.normal(size=(20, 3)) * radii[pick] * 3
    qr = rng.uniform(0, 2, 20) * radii[pick]
    lo, hi = row_candidates(s, n, c0, r0, qc, qr)
    hit = np.linalg.norm(qc[:, None] - centers[None], axis=2) <= qr[:, None] + radii[None]
    for t in range(20):
        ks = np.nonzero(hit[t])[0]
        assert np.all((ks >= lo[t]) & (ks <= hi[t]))


def test_bad_queries_raise():
    lat = lattice_of("1")
    with pytest.raises(Exception, match="radii"):
        biq.query(lat, np.zeros((2, 3)), np.array([0.1, -1]))
    with pytest.raises(Exception, match="NaN"):
        biq.any_hit(lat, np.array([[0, np.nan, 0]]), np.array([0.1]))
    with pytest.raises(Exception, match="method"):
        biq.query(lat, np.zeros((1, 3)), np.ones(1), method="fast")


def test_cli_biq(tmp_path, capsys):
    q = np.array([[0.0, 0, 0, 0.2], [2, 2, 2, 0.3], [50, 50, 50, 0.1]])
    np.save(tmp_path / "q.npy", q)
    out = tmp_path / "h.json"
    assert main(["biq", "bcc", "--param", "n=4", "--queries", str(tmp_path / "q.npy"), "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    ref = biq.query(load_lattice("bcc", ["n=4"]), q[:, :3], q[:, 3], "naive")
    assert [x["nodes"] for x in doc["queries"]] == [x.nodes.tolist() for x in ref]
    assert [x["beams"] for x in doc["queries"]] == [x.beams.tolist() for x in ref]
    assert doc["queries"][2] == {"nodes": [], "beams": []}
    for bad in (np.zeros((2, 3)), np.array([[0, 0, 0, -1.0]]), np.array([[np.nan, 0, 0, 1.0]])):
        np.save(tmp_path / "bad.npy", bad)
        bad_out = tmp_path / "bad.json"
        assert main(["biq", "bcc", "--queries", str(tmp_path / "bad.npy"), "--out", str(bad_out)]) == 2
        assert not bad_out.exists()
    assert "queries" in capsys.readouterr().err


def path_lattices(rng, path):
    """Lattices on which a path runs (detected, or forced below a faster path): the cylindrical
    case (its i-sheets culled by the common axis), the O(1) cases, placed ones, the thesis
    presets and random lattices of every kind (for O(ū), those whose detected path is not the
    general one); for O(ūv̄) also the wrapping cases and the warped preset."""
    lats = [lattice_of("u"), lattice_of("1"), lattice_of("1-polar"),
            load_lattice("thesis_cylindrical", ["nu=3", "nv=12", "nw=3"]), load_lattice("thesis_regular", ["n=4"]),
            load_lattice("lil_cylindrical_coarse")]
    if path == "uv":
        lats += [lattice_of("wrap"), lattice_of("wrap-swirl"), load_lattice("thesis_warped", ["n=6"])]
    placed = lattice_of("u")
    placed.set_placement(Swirl(0.7, [1, 1, 0], [0.5, 0, 2], 1.3))
    lats.append(placed)
    while len(lats) < 16:
        lat = random_lattice(rng, [KINDS[int(x)] for x in rng.integers(0, len(KINDS), 3)])
        if path == "uv" or cached_plan(lat).path != "uv":
            lats.append(lat)
    return lats


@pytest.mark.skipif(rangefinder._compiled is None, reason="the compiled RangeFinder is not built")
@pytest.mark.parametrize("path", ["u", "uv"])
def test_compiled_paths_equal_their_numpy_forms(monkeypatch, path):
    """Bit for bit: the compiled O(ū) and O(ūv̄) paths' hits, row for row, equal their numpy
    forms', and the naive path's."""
    rng = np.random.default_rng(31 + len(path))
    for lat in path_lattices(rng, path):
        for scale in (0.5, 4.0):
            c, r = random_queries(rng, lat, 40, scale)
            got = rangefinder.lattice_hits(lat, c, r, path=path)
            with monkeypatch.context() as m:
                m.setattr(rangefinder, "_compiled", None)
                want = rangefinder.lattice_hits(lat, c, r, path=path)
            assert got[2] == want[2] == path
            for a, b in zip(got[:2], want[:2]):
                assert np.array_equal(_unique_rows(a), _unique_rows(b))
            assert_same(biq.query(lat, c, r, "naive"), split_hits(len(c), got[0], got[1], path))
