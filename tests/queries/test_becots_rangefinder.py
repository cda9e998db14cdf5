"""BeCOTS RangeFinder (thesis §8) code paths, each against the naive BIQ (exact tests of every
element): candidate windows across the theta seam, several branches, shape selections, the
cached per-lattice plan and its invalidation, the per-index tables, the key-overflow sort and
the dk != 0 special cases."""

from __future__ import annotations

import numpy as np
import pytest
from ple.algebra.similarity import Rotation, Translation
from ple.model.becots import BeCOTSField
from ple.model.becots_builders import becots_lattice, stack_lattice
from ple.queries import becots_rangefinder as brf
from ple.queries import biq
from ple.queries.plans import forget

CORNERS = [[0, 0, 0], [0, 3, 0.5], [3.5, 3.2, 1.5], [3, 0, 0.2]]


def _near_queries(lat, rng, n, spread=1.0):
    ev = lat.evaluate()
    idx = rng.integers(0, len(ev.center), n)
    c = ev.center[idx] + rng.normal(size=(n, 3)) * ev.radius[idx, None] * spread
    return c, ev.radius[idx] * rng.uniform(0, 2, n)


def _assert_same(lat, c, r):
    got, ref = biq.query(lat, c, r), biq.query(lat, c, r, method="naive")
    assert all(g.path == "becots" for g in got)
    for g, e in zip(got, ref):
        assert np.array_equal(g.nodes, e.nodes) and np.array_equal(g.beams, e.beams)
    return sum(len(e.nodes) + len(e.beams) for e in ref)


def test_candidate_windows_across_the_theta_seam(rng):
    # the lattice turns 0 .. ~4.1 rad about the axis: it crosses theta = ±π, where arctan2 jumps
    f = BeCOTSField.from_controls((0.3, 3.6, 0.2, 0.5), beta=0.6)
    lat = becots_lattice(f, (24, 6), "kagome", 0.15)
    c, r = _near_queries(lat, rng, 300)
    _, theta = f.log_polar(c)
    seam = np.abs(np.abs(theta) - np.pi) < 0.4
    assert (seam & (theta < 0)).sum() > 5 and (seam & (theta > 0)).sum() > 5
    assert _assert_same(lat, c[seam], r[seam]) > 0
    _assert_same(lat, c, r)


def test_several_branches_per_query(rng):
    # U turns 9 rad > 2π: the map overlaps itself, a query meets the lattice in two branches
    f = BeCOTSField.from_controls((0.05, 9.0, 0.05, 0.8), beta=1.2)
    lat = becots_lattice(f, (30, 4), "triangle", 0.2)
    c, r = _near_queries(lat, rng, 200, spread=2.0)
    layer = brf._plan(lat).layers[0]
    _, rows, _, _, _ = layer.query_bounds(c, r)
    assert rows is not None and len(rows) > len(c)  # some queries get more than one branch
    assert _assert_same(lat, c, r) > 0


def test_queries_on_the_axis_every_branch(rng):
    f = BeCOTSField.from_controls((0.2, 2.5, 0.3, 1.5), beta=0.4)
    lat = becots_lattice(f, (8, 8), "honeycomb", 0.2)
    t = rng.uniform(0.5, 4, 60)
    c = f.apex + t[:, None] * f.axis
    assert _assert_same(lat, c, rng.uniform(0.5, 3, 60)) > 0


def test_shape_selection_matches_filtered_naive(rng):
    lat = becots_lattice(BeCOTSField.from_corners(*CORNERS), (7, 6), "kagome", 0.12)
    c, r = _near_queries(lat, rng, 150, spread=1.5)
    ref = biq.query(lat, c, r, method="naive")
    nodes, beams = [0, 2], [1, 4, 5]
    got = brf.query_subset(lat, c, r, nodes=nodes, beams=beams)
    for g, e in zip(got, ref):
        assert np.array_equal(g.nodes, e.nodes[np.isin(e.nodes[:, 3], nodes)])
        assert np.array_equal(g.beams, e.beams[np.isin(e.beams[:, 3], beams)])
    # per-query selection with repeated entries (padding): positions in nodes + beams
    sel = rng.integers(0, len(nodes) + len(beams), (len(c), 4))
    sel[:, 3] = sel[:, 0]
    got = brf.query_subset(lat, c, r, nodes=nodes, beams=beams, select=sel)
    for t, (g, e) in enumerate(zip(got, ref)):
        ids = np.array(nodes + [len(lat.nodes) + b for b in beams])[sel[t]]
        keep_n = np.isin(e.nodes[:, 3], ids[ids < len(lat.nodes)])
        keep_b = np.isin(e.beams[:, 3], ids[ids >= len(lat.nodes)] - len(lat.nodes))
        assert np.array_equal(g.nodes, e.nodes[keep_n]) and np.array_equal(g.beams, e.beams[keep_b])


def test_plan_is_cached_and_rebuilt_when_the_lattice_changes(rng):
    lat = becots_lattice(BeCOTSField.from_corners(*CORNERS), (6, 6), "triangle", 0.1)
    c, r = _near_queries(lat, rng, 120, spread=2.0)
    _assert_same(lat, c, r)
    plan = brf._plan(lat)
    assert brf._plan(lat) is plan  # cached on the lattice
    lat.nodes[0].radius *= 1.7  # a template change
    assert brf._plan(lat) is not plan
    _assert_same(lat, c, r)
    lat.add_beam(0, 0, 2, -1)
    _assert_same(lat, c, r)
    lat.set_placement(Rotation(0.4, [0, 1, 0], [1, 1, 1]))
    c2, r2 = _near_queries(lat, rng, 120, spread=2.0)
    _assert_same(lat, c2, r2)
    lat.set_w(3, Translation([0, 0, 0.7]))
    c3, r3 = _near_queries(lat, rng, 120, spread=2.0)
    assert _assert_same(lat, c3, r3) > 0


def test_without_tables_and_with_the_overflow_sort(rng, monkeypatch):
    f = BeCOTSField.from_controls((0.4, 4.0, 0.3, 2.5), beta=0.5)
    lat = becots_lattice(f, (12, 9), "kagome", 0.12, closed=True)
    c, r = _near_queries(lat, rng, 150, spread=1.5)
    ref = [(x.nodes, x.beams) for x in biq.query(lat, c, r, method="naive")]
    for table_limit, key_limit in ((0, brf.KEY_LIMIT), (brf.TABLE_LIMIT, 0), (0, 0)):
        monkeypatch.setattr(brf, "TABLE_LIMIT", table_limit)
        monkeypatch.setattr(brf, "KEY_LIMIT", key_limit)
        forget(lat)
        got = biq.query(lat, c, r)
        assert all(np.array_equal(g.nodes, n) and np.array_equal(g.beams, b) for g, (n, b) in zip(got, ref))
    cyl = BeCOTSField("cylinder", np.array([2.0, 0, 0]), np.zeros(3), np.array([0, 0, 1.0]), (1.0, 1.0), (0.2, -2.0))
    lat = becots_lattice(cyl, (7, 7), "triangle", 0.1)
    monkeypatch.setattr(brf, "TABLE_LIMIT", 0)
    assert _assert_same(lat, *_near_queries(lat, rng, 80)) > 0


@pytest.mark.parametrize("nw", [1, 2])
def test_beam_patterns_across_w(rng, nw):
    # special case dk != 0: no instance when W count is 1; with W count > 1 the general path
    lat = becots_lattice(BeCOTSField.from_corners(*CORNERS), (5, 5), "triangle", 0.1)
    lat.set_w(nw, Translation([0, 0, 0.5]))
    lat.add_beam(0, 0, 1, 0, 1)
    c, r = _near_queries(lat, rng, 100, spread=2.0)
    got, ref = biq.query(lat, c, r), biq.query(lat, c, r, method="naive")
    assert all(np.array_equal(g.nodes, e.nodes) and np.array_equal(g.beams, e.beams) for g, e in zip(got, ref))
    assert all(g.path == ("becots" if nw == 1 else g.path) for g in got)
    assert sum(len(e.beams) for e in ref) > 0


def test_stack_all_layers(rng):
    lat = stack_lattice(BeCOTSField.from_corners(*CORNERS), (5, 5), 4, 0.3, "normal", "triangle", 0.1,
                        links=((0, 0, 0, 0),))
    assert _assert_same(lat, *_near_queries(lat, rng, 120, spread=1.5)) > 0
