"""Filters (thesis §9): stencils, LiL and cascades against brute force over every node and element."""

from __future__ import annotations

import numpy as np
import pytest
from lattices import KINDS, centre_on, random_lattice
from ple.cli.common import parse_stencil
from ple.errors import PleError
from ple.filters.base import FilteredLattice
from ple.filters.lil import LiL, lil
from ple.filters.stencil import Stencil
from ple.model.lattice import Lattice


# ----- brute force: every query ball against every element, nearest point by ternary search --------
def brute_beam_gap(p, r, c1, r1, c2, r2, iters: int = 200):
    """min over s in [0, 1] of |p - c(s)| - r(s) - r, by ternary search on the convex function."""
    lo, hi = np.zeros(len(p)), np.ones(len(p))

    def f(s):
        return np.linalg.norm(p - (c1 + s[:, None] * (c2 - c1)), axis=1) - (r1 + s * (r2 - r1)) - r

    for _ in range(iters):
        a, b = lo + (hi - lo) / 3, hi - (hi - lo) / 3
        left = f(a) < f(b)
        hi = np.where(left, b, hi)
        lo = np.where(left, lo, a)
    return np.minimum(f((lo + hi) / 2), np.minimum(f(np.zeros(len(p))), f(np.ones(len(p)))))


def brute_hits(center, radius, el_center, el_radius, el_beams):
    """bool (N,): does query ball n touch any ball or beam of the element arrays."""
    hit = np.zeros(len(center), dtype=bool)
    for c, r in zip(el_center, el_radius):
        hit |= np.linalg.norm(center - c, axis=1) <= radius + r
    for a, b in el_beams:
        n = len(center)
        gap = brute_beam_gap(center, radius, np.tile(el_center[a], (n, 1)), np.full(n, el_radius[a]),
                             np.tile(el_center[b], (n, 1)), np.full(n, el_radius[b]))
        hit |= gap <= 0
    return hit


def brute_select(lat: Lattice, keep):
    """Sets of surviving node indices and beam indices, from the full evaluation and a node mask."""
    ev = lat.evaluate()
    nodes = {tuple(x) for x in ev.node_index[keep]}
    alive = keep[ev.beam_nodes[:, 0]] & keep[ev.beam_nodes[:, 1]]
    beams = {tuple(x) for x in ev.beam_index[alive]}
    return nodes, beams


def as_sets(ev):
    nodes = {tuple(x) for x in ev.node_index}
    beams = {tuple(x) for x in ev.beam_index}
    # beam_nodes must point at the right surviving rows
    assert len(beams) == len(ev.beam_index) and len(nodes) == len(ev.node_index)
    return nodes, beams


def check_beam_rows(lat: Lattice, ev):
    for (i, j, k, p), (a, b) in zip(ev.beam_index, ev.beam_nodes):
        bp = lat.beams[p]
        assert tuple(ev.node_index[a]) == (i, j, k, bp.n1)
        assert tuple(ev.node_index[b]) == (i + bp.di, j + bp.dj, k + bp.dk, bp.n2)


def brute_lil_mask(fine: Lattice, coarse_ev):
    ev = fine.evaluate()
    return brute_hits(ev.center, ev.radius, coarse_ev.center, coarse_ev.radius, coarse_ev.beam_nodes)


def brute_filtered(lat: Lattice, keep):
    """An Evaluation-like of lat's surviving elements (from a brute mask) for cascades."""

    return lat.evaluate().select(keep)


def pair(seed: int, kind: str):
    rng = np.random.default_rng(seed)
    other = list(rng.choice(KINDS, 2))
    fine = random_lattice(rng, [kind] + other, (5, 4, 4), step=1.0, radius=0.12)
    other = list(rng.choice(KINDS, 2))
    coarse = random_lattice(rng, other + [kind], (3, 3, 2), step=1.8, radius=0.3, nodes=1)
    centre_on(coarse, fine)
    return rng, fine, coarse


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [1, 3, 4])
def test_lil_matches_brute_force(kind, seed):
    _, fine, coarse = pair(seed, kind)
    ev = lil(fine, coarse).evaluate()
    keep = brute_lil_mask(fine, coarse.evaluate())
    assert as_sets(ev) == brute_select(fine, keep)
    check_beam_rows(fine, ev)


@pytest.mark.parametrize("kind", KINDS)
def test_cascade_matches_brute_force(kind):
    rng, fine, medium = pair(10 + KINDS.index(kind), kind)
    coarse = random_lattice(rng, [kind, "translation", "rotation"], (2, 2, 2), step=2.5, radius=0.5, nodes=1)
    centre_on(coarse, medium)
    ev = lil(fine, medium, coarse).evaluate()
    medium_keep = brute_lil_mask(medium, coarse.evaluate())
    medium_ev = brute_filtered(medium, medium_keep)
    keep = brute_lil_mask(fine, medium_ev)
    assert as_sets(ev) == brute_select(fine, keep)
    check_beam_rows(fine, ev)


def brute_stencil(lat: Lattice, s):
    ev = lat.evaluate()
    return np.array([s[i % s.shape[0], j % s.shape[1], k % s.shape[2]] if s.ndim == 3
                     else s[i % s.shape[0], j % s.shape[1], k % s.shape[2], n]
                     for i, j, k, n in ev.node_index], dtype=bool)


@pytest.mark.parametrize("kind", KINDS)
def test_stencil_and_compounds_match_brute_force(kind):
    rng, fine, coarse = pair(20 + KINDS.index(kind), kind)
    s3 = rng.random((2, 3, 2)) < 0.6
    s4 = rng.random((3, 2, 2, 2)) < 0.6
    st3, st4 = Stencil(s3), Stencil(s4)
    b3, b4 = brute_stencil(fine, s3), brute_stencil(fine, s4)
    blil = brute_lil_mask(fine, coarse.evaluate())
    lf = LiL(coarse)
    cases = [(st3, b3), (st4, b4), (st3 & lf, b3 & blil), (st4 | lf, b4 | blil), (~st3 & lf, ~b3 & blil),
             (~(st3 | st4), ~(b3 | b4))]
    for flt, truth in cases:
        ev = FilteredLattice(fine, flt).evaluate()
        assert as_sets(ev) == brute_select(fine, truth)
        check_beam_rows(fine, ev)
    # stencil inside a cascade: the medium level is stencil-filtered
    medium_f = FilteredLattice(coarse, Stencil(np.array([[[True, False]]])))
    ev = FilteredLattice(fine, LiL(medium_f)).evaluate()
    ckeep = brute_stencil(coarse, np.array([[[True, False]]]))
    keep = brute_lil_mask(fine, brute_filtered(coarse, ckeep))
    assert as_sets(ev) == brute_select(fine, keep)


def test_region_is_lazy_and_consistent():
    _, fine, coarse = pair(7, "swirl")
    flt = Stencil.named("faces", 2) & LiL(coarse)
    full = FilteredLattice(fine, flt).evaluate()
    part = FilteredLattice(fine, flt).evaluate("1:4,0:3,1:4")
    inside = lambda x: 1 <= x[0] < 4 and 0 <= x[1] < 3 and 1 <= x[2] < 4  # noqa: E731
    assert {tuple(x) for x in part.node_index} == {tuple(x) for x in full.node_index if inside(x)}
    for a, b in part.beam_nodes:
        assert inside(part.node_index[a]) and inside(part.node_index[b])
    check_beam_rows(fine, part)
    full_beams = {tuple(x) for x in full.beam_index}
    assert {tuple(x) for x in part.beam_index} <= full_beams


def test_named_stencils():
    e = Stencil.named("edges", 3).array
    assert e.shape == (3, 3, 3) and e.sum() == 7  # the three axes through the corner group
    assert Stencil.named("faces", 3).array.sum() == 27 - 8
    assert Stencil.named("corners", (2, 3, 4)).array.sum() == 1
    c = Stencil.named("checker", 4).array
    assert c.sum() == 32 and c[0, 0, 0] and not c[2, 0, 0]
    assert parse_stencil("layers:2x2x5:2").array.sum() == 2 * 2 * 2


@pytest.mark.parametrize("bad", ["nope:4", "edges:0", "edges:a", "edges:2x2", "edges:2:0", "x.npy"])
def test_bad_stencils(bad):
    with pytest.raises(PleError):
        parse_stencil(bad)


def test_bad_filter_inputs():
    with pytest.raises(PleError):
        Stencil(np.ones((2, 2)))
    with pytest.raises(PleError):
        Stencil(np.full((2, 2, 2), 3))
    with pytest.raises(PleError):
        LiL("coarse")
    with pytest.raises(PleError):
        lil(Lattice())
    lat = Lattice()
    lat.add_node([0, 0, 0], 0.1)
    with pytest.raises(PleError, match="node columns"):
        FilteredLattice(lat, Stencil(np.ones((1, 1, 1, 3), bool))).evaluate()


# ----- command line --------------------------------------------------------------------------------
def test_cli_lil_cascade_matches_api(tmp_path, capsys):
    from ple.cli.main import main
    from ple.program.sources import load_lattice

    out = tmp_path / "lil.npz"
    argv = ["lil", "thesis_regular", "--param", "n=12", "--coarse", "lil_regular_coarse:n=4,span=11",
            "--coarse", "cubic:n=2,cell=11,radius=0.15", "--out", str(out)]
    assert main(argv) == 0
    fine = load_lattice("thesis_regular", {"n": 12})
    medium = load_lattice("lil_regular_coarse", {"n": 4, "span": 11.0})
    coarse = load_lattice("cubic", {"n": 2, "cell": 11.0, "radius": 0.15})
    ev = lil(fine, medium, coarse).evaluate()
    with np.load(out) as z:
        for key, value in ev.arrays().items():
            assert np.array_equal(z[key], value), key
    assert 0 < len(ev.beam_index) < len(lil(fine, medium).evaluate().beam_index)
    assert "nodes" in capsys.readouterr().out


def test_cli_lil_with_stencil_and_region(tmp_path):
    from ple.cli.main import main
    from ple.program.sources import load_lattice

    out = tmp_path / "s.npz"
    assert main(["lil", "bcc", "--param", "n=10", "--coarse", "cubic:n=3,cell=4.5,radius=0.1",
                 "--stencil", "faces:2", "--region", "0:8,2:10,0:10", "--out", str(out)]) == 0
    fine = load_lattice("bcc", {"n": 10})
    coarse = load_lattice("cubic", {"n": 3, "cell": 4.5, "radius": 0.1})
    ev = FilteredLattice(fine, Stencil.named("faces", 2) & LiL(coarse)).evaluate("0:8,2:10,0:10")
    with np.load(out) as z:
        assert np.array_equal(z["beam_index"], ev.beam_index) and np.array_equal(z["node_index"], ev.node_index)


@pytest.mark.parametrize("argv", [
    ["lil", "bcc", "--out", "X"],
    ["lil", "bcc", "--coarse", "nosuch", "--out", "X"],
    ["lil", "bcc", "--coarse", "cubic", "--stencil", "nope", "--out", "X"],
    ["lil", "bcc", "--coarse", "cubic:n=0", "--out", "X"],
    ["lil", "bcc", "--coarse", "cubic", "--region", "0:99,0:1,0:1", "--out", "X"],
    ["filter", "bcc", "--out", "X"],
    ["filter", "bcc", "--implicit", "blob", "--out", "X"],
])
def test_cli_bad_input(tmp_path, capsys, argv):
    from ple.cli.main import main

    argv = [str(tmp_path / "o.npz") if a == "X" else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error" in err
    assert list(tmp_path.iterdir()) == []


def test_program_filters_are_honoured():
    # a lattice carrying its own filter (Lattice.set_filter) filters its own level of a LiL
    _, fine, coarse = pair(5, "rotation")
    stencil = Stencil(np.array([[[True, False]]]))
    coarse_own = coarse.copy()
    coarse_own.set_filter(stencil)
    expected = FilteredLattice(fine, LiL(FilteredLattice(coarse, stencil))).evaluate()
    assert as_sets(lil(fine, coarse_own).evaluate()) == as_sets(expected)
    assert as_sets(FilteredLattice(fine, LiL(coarse_own)).evaluate()) == as_sets(expected)
    fine_own = fine.copy()
    fine_own.set_filter(Stencil.named("faces", 2))
    expected = FilteredLattice(fine, Stencil.named("faces", 2) & LiL(coarse)).evaluate()
    assert as_sets(lil(fine_own, coarse).evaluate()) == as_sets(expected)
    # the RangeFinder path honours the coarse lattice's own filter too (one truth): same kept set
    by_biq = FilteredLattice(fine, LiL(coarse_own, method="biq")).evaluate()
    assert as_sets(by_biq) == as_sets(FilteredLattice(fine, LiL(coarse_own)).evaluate())


def test_cli_filter_applies_the_programs_own_filter(tmp_path):
    from ple.cli.main import main
    from ple.program.sources import load_lattice

    out = tmp_path / "h.npz"
    assert main(["filter", "hier_lil2", "--param", "n=10", "--stencil", "checker:4", "--out", str(out)]) == 0
    lat = load_lattice("hier_lil2", {"n": 10})
    ev = FilteredLattice(lat, lat.filter & Stencil.named("checker", 4)).evaluate()
    with np.load(out) as z:
        assert np.array_equal(z["beam_index"], ev.beam_index)
    assert 0 < len(ev.beam_index) < len(FilteredLattice(lat, lat.filter).evaluate().beam_index)
