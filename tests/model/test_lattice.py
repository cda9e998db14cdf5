"""Lazy evaluation of steady lattices against W^k V^j U^i computed by matrix powers."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import reference_matrix
from lattices import random_similarity_matrix
from ple import Lattice, PleError, Pt, Similarity, Translation, Vec, load_lattice
from ple.program.presets import preset_names


def random_lattice(rng, counts=(4, 5, 3), nodes=2):
    lat = Lattice()
    for _ in range(nodes):
        lat.add_node(rng.normal(size=3) * 0.3, rng.uniform(0.05, 0.2))
    lat.add_beam(0, nodes - 1, 1, 0, 0)
    lat.add_beam(0, 0, 0, 1, 0)
    lat.add_beam(nodes - 1, 0, 0, -1, 1)
    mats = [random_similarity_matrix(rng) for _ in range(4)]
    lat.set_u(counts[0], Similarity.from_matrix(mats[0]))
    lat.set_v(counts[1], Similarity.from_matrix(mats[1]))
    lat.set_w(counts[2], Similarity.from_matrix(mats[2]))
    lat.set_placement(Similarity.from_matrix(mats[3]))
    return lat, mats


def brute_force_nodes(lat, mats):
    """Every node by explicit matrix powers: G W^k V^j U^i c, radius times the product of scales."""
    out = {}
    mu, mv, mw, g = mats
    for i in range(lat.counts[0]):
        for j in range(lat.counts[1]):
            for k in range(lat.counts[2]):
                m = g @ np.linalg.matrix_power(mw, k) @ np.linalg.matrix_power(mv, j) @ np.linalg.matrix_power(mu, i)
                s = abs(np.linalg.det(m[:3, :3])) ** (1 / 3)
                for n, node in enumerate(lat.nodes):
                    out[(i, j, k, n)] = ((m @ np.append(node.center, 1))[:3], node.radius * s)
    return out


def test_evaluate_matches_matrix_powers(rng):
    for _ in range(5):
        lat, mats = random_lattice(rng)
        ev = lat.evaluate()
        ref = brute_force_nodes(lat, mats)
        assert len(ev.node_index) == len(ref)
        for row, idx in enumerate(map(tuple, ev.node_index)):
            c, r = ref[idx]
            assert np.abs(ev.center[row] - c).max() <= 1e-9 * max(1, np.abs(c).max())
            assert ev.radius[row] == pytest.approx(r, rel=1e-9)
        c, r = lat.node_balls(ev.node_index[::-1])
        assert np.allclose(c, ev.center[::-1], rtol=1e-12, atol=1e-12)


def test_beams_exist_exactly_where_both_groups_exist(rng):
    lat, _ = random_lattice(rng, counts=(3, 4, 2))
    ev = lat.evaluate()
    rows = {tuple(x): n for n, x in enumerate(ev.node_index)}
    expected = set()
    for p, b in enumerate(lat.beams):
        for i in range(3):
            for j in range(4):
                for k in range(2):
                    t = (i + b.di, j + b.dj, k + b.dk)
                    if 0 <= t[0] < 3 and 0 <= t[1] < 4 and 0 <= t[2] < 2:
                        expected.add((i, j, k, p, rows[(i, j, k, b.n1)], rows[(*t, b.n2)]))
    got = {(*map(int, bi), *map(int, bn)) for bi, bn in zip(ev.beam_index, ev.beam_nodes)}
    assert got == expected
    assert lat.beam_count() == len(expected)
    # sorted by (i, j, k, pattern)
    assert (np.lexsort(ev.beam_index.T[::-1]) == np.arange(len(ev.beam_index))).all()


def test_region_is_the_sub_box_of_the_full_evaluation(rng):
    lat, _ = random_lattice(rng, counts=(5, 4, 4))
    full = lat.evaluate()
    part = lat.evaluate("1:4,2:4,0:3")
    keep = ((full.node_index[:, 0] >= 1) & (full.node_index[:, 0] < 4) & (full.node_index[:, 1] >= 2)
            & (full.node_index[:, 2] < 3))
    assert (part.node_index == full.node_index[keep]).all()
    assert np.allclose(part.center, full.center[keep])
    # beams of the region join region rows and have both ends inside
    assert (part.node_index[part.beam_nodes[:, 0], :3] == part.beam_index[:, :3]).all()


def test_beams_of_pattern_validity(rng):
    lat, _ = random_lattice(rng, counts=(3, 3, 3))
    valid, start, end = lat.beams_of_pattern(2, [0, 0, 2], [1, 0, 1], [0, 2, 1])
    # pattern 2 has offset (0, -1, 1)
    assert valid.tolist() == [True, False, True]
    assert np.allclose(start[0][0], lat.node_balls([[0, 1, 0, lat.beams[2].n1]])[0][0])
    assert np.allclose(end[0][2], lat.node_balls([[2, 0, 2, lat.beams[2].n2]])[0][0])


def test_steady_row_along_w_and_slabs_cover_everything(rng):
    lat, mats = random_lattice(rng, counts=(3, 3, 6))
    c, r = lat.row_w(1, 2, 0)
    ref = brute_force_nodes(lat, mats)
    assert np.allclose(c, [ref[(1, 2, k, 0)][0] for k in range(6)], atol=1e-9)
    seen = []
    for box in lat.iter_slabs(max_groups=4):
        assert box.groups <= 4
        seen.extend(map(tuple, lat.evaluate(box).node_index))
    assert sorted(seen) == sorted(map(tuple, lat.evaluate().node_index))


def test_bounds_contain_all_balls(rng):
    lat, _ = random_lattice(rng)
    lo, hi = lat.bounds()
    ev = lat.evaluate()
    assert np.allclose(lo, (ev.center - ev.radius[:, None]).min(0))
    assert np.allclose(hi, (ev.center + ev.radius[:, None]).max(0))


def test_cumulative_direction_reaches_the_last_group():
    lat = Lattice()
    lat.add_node(Pt(1, 0, 0), 0.1)
    s = Similarity.from_matrix(reference_matrix("swirl", angle=2.0, axis=[0, 0, 1], point=[0, 0, 0], factor=2.0))
    lat.set_u(5, s, cumulative=True)
    c, r = lat.node_balls([[4, 0, 0, 0]])
    assert np.allclose(c[0], s.apply_points([1, 0, 0])) and r[0] == pytest.approx(0.2)


def test_mean_radius_closed_form(rng):
    lat, _ = random_lattice(rng)
    assert lat.mean_radius() == pytest.approx(lat.evaluate().radius.mean(), rel=1e-9)


def test_million_nodes_memory_is_proportional_to_request():
    lat = load_lattice("cubic", {"n": 100})
    c, r = lat.region_balls()
    assert c.shape == (100, 100, 100, 1, 3)
    assert np.allclose(c[7, 3, 99, 0], [7, 3, 99])
    # a single far row of a 10^21-node-sized index space is cheap: only what is asked is evaluated
    big = lat.with_counts(10**6, 10**6, 10**6)
    c, _ = big.node_balls([[999_999, 5, 123_456, 0]])
    assert np.allclose(c[0], [999_999, 5, 123_456])


@pytest.mark.parametrize("bad, message", [
    (lambda lat: lat.set_u(0, Translation(Vec(1, 0, 0))), "at least 1"),
    (lambda lat: lat.set_u(2.5, Translation(Vec(1, 0, 0))), "integer"),
    (lambda lat: lat.set_v(10**9, Translation(Vec(1, 0, 0))), "absurdly large"),
    (lambda lat: lat.add_node(Pt(0, 0, 0), -1), "positive"),
    (lambda lat: lat.add_node(Pt(0, float("nan"), 0), 1), "finite"),
    (lambda lat: lat.add_beam(0, 7, 1, 0, 0), "unknown node id 7"),
    (lambda lat: lat.add_beam("x", 0, 1, 0, 0), "unknown node id 'x'"),
    (lambda lat: lat.add_beam(0, 0, 0, 0, 0), "no length"),
    (lambda lat: lat.region("0:5,0:1,0:1"), "outside"),
])
def test_bad_input(bad, message):
    lat = Lattice()
    lat.add_node(Pt(0, 0, 0), 0.1)
    with pytest.raises(PleError, match=message):
        bad(lat)


def test_remove_node_drops_its_beams():
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.1, "a")
    b = lat.add_node(Pt(0.5, 0, 0), 0.1, "b")
    c = lat.add_node(Pt(0, 0.5, 0), 0.1, "c")
    lat.add_beam(a, b)
    lat.add_beam(b, c)
    lat.add_beam(c, a, 1, 0, 0)
    lat.remove_node("b")
    assert [(x.n1, x.n2) for x in lat.beams] == [(1, 0)]
    assert lat.node_id("c") == 1


@pytest.mark.parametrize("name", preset_names())
def test_every_preset_builds_and_evaluates(name):
    lat = load_lattice(name)
    small = lat.region(f"0:{min(3, lat.counts[0])},0:{min(3, lat.counts[1])},0:{min(3, lat.counts[2])}")
    full = lat.evaluate_unfiltered(small)
    assert len(full.center) == small.groups * len(lat.nodes)
    assert np.isfinite(full.center).all() and (full.radius > 0).all()
    ev = lat.evaluate(small)  # the one evaluation: what the program's filter keeps, nothing else
    want = full.select(lat.keeps(full.node_index))
    assert np.array_equal(ev.node_index, want.node_index) and np.array_equal(ev.beam_index, want.beam_index)
    assert np.array_equal(ev.center[ev.beam_nodes], want.center[want.beam_nodes])


def test_program_filters_apply_in_eval(tmp_path):
    """A program may attach a filter (thesis §9); ple eval keeps exactly the accepted nodes."""
    from ple.cli.main import main
    from ple.filters.stencil import Stencil
    lat = load_lattice("hier_stencil", {"n": 8, "period": 3})
    keep = Stencil.named("edges", 3, 1).node_mask(lat, lat.evaluate().node_index, None, None)
    out = tmp_path / "e.npz"
    assert main(["eval", "hier_stencil", "--param", "n=8", "--param", "period=3", "--out", str(out)]) == 0
    z = np.load(out)
    full = lat.evaluate()
    assert sorted(map(tuple, z["node_index"])) == sorted(map(tuple, full.node_index[keep]))
    kept = {tuple(x) for x in z["node_index"]}
    for a, b in z["beam_nodes"]:
        assert tuple(z["node_index"][a]) in kept and tuple(z["node_index"][b]) in kept
    with pytest.raises(PleError, match="filter"):
        lat.set_filter(42)


def test_with_filter_ands_after_the_own_filter():
    from ple.filters.stencil import Stencil

    lat = load_lattice("cubic", {"n": 4})
    assert lat.with_filter(None).filter is None
    own = Stencil.named("checker", 2)
    lat.set_filter(own)
    assert lat.with_filter(None).filter is own  # nothing added: the program's filter stays
    both = lat.with_filter(Stencil.named("layers", 2))
    want = lat.evaluate_unfiltered()
    keep = own.node_mask(lat, want.node_index, want.center, want.radius) & (want.node_index[:, 2] % 2 == 0)
    assert np.array_equal(both.evaluate().node_index, want.node_index[keep])
    assert lat.unfiltered().filter is None and lat.filter is own
