"""Unclean pairs and gaps: the steady path (anchors moved by similarities) and the explicit grid path
against a brute-force test of all element pairs; the exact beam–beam gap against dense sampling."""

from __future__ import annotations

import numpy as np
import pytest
from ple.algebra.elements import beam_beam_gap, beam_distance, segment_distance
from ple.algebra.similarity import Rotation, Scaling, Screw, Translation
from ple.errors import PleError
from ple.filters.stencil import Stencil
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice
from ple.queries.overlaps import KINDS, candidate_pairs, grid_pairs, pair_gaps, unclean_pairs


def test_beam_beam_gap_vs_sampling():
    rng = np.random.default_rng(5)
    t = np.linspace(0, 1, 1201)
    for _ in range(40):
        a1, b1, a2, b2 = rng.normal(size=(4, 3)) * 1.5
        r = rng.uniform(0.05, 0.6, 4)
        gap = float(beam_beam_gap(a1, r[0], b1, r[1], a2, r[2], b2, r[3]))
        p = a1 + t[:, None] * (b1 - a1)
        sampled = np.maximum(beam_distance(p, a2, r[2], b2, r[3]) - (r[0] + t * (r[1] - r[0])), 0).min()
        assert gap <= sampled + 1e-12
        assert gap == pytest.approx(sampled, abs=2e-5)
        # the axis distance minus the largest radii never exceeds the gap (a safe lower bound)
        assert segment_distance(a1, b1, a2, b2) - max(r[:2]) - max(r[2:]) <= gap + 1e-12


def _brute(ev, margin):
    """Every pair of elements of an evaluation: counts of overlapping non-incident pairs per kind
    and the smallest gap below margin (the exact gap of each pair whose boxes come within it)."""
    nn, nb = len(ev.radius), len(ev.beam_nodes)
    ends = np.concatenate([np.repeat(np.arange(nn)[:, None], 2, axis=1), ev.beam_nodes])
    kinds = np.concatenate([np.zeros(nn, np.int64), np.ones(nb, np.int64)])
    edges = {tuple(sorted(e)) for e in ev.beam_nodes.tolist()}
    i, j = np.triu_indices(nn + nb, 1)
    ia, ib = ends[i], ends[j]
    shared = (ia[:, :1] == ib).any(axis=1) | (ia[:, 1:] == ib).any(axis=1)
    joined = np.array([kinds[x] == 0 and kinds[y] == 0 and tuple(sorted((x, y))) in edges for x, y in zip(i, j)],
                      bool).reshape(-1)
    # pairs whose boxes lie more than the margin apart can neither overlap nor come within it
    ball_lo, ball_hi = ev.center - ev.radius[:, None], ev.center + ev.radius[:, None]
    lo = np.minimum(ball_lo[ends[:, 0]], ball_lo[ends[:, 1]])
    hi = np.maximum(ball_hi[ends[:, 0]], ball_hi[ends[:, 1]])
    near = np.all((lo[i] <= hi[j] + margin + 1e-9) & (lo[j] <= hi[i] + margin + 1e-9), axis=1)
    keep = ~shared & ~joined & near
    i, j, ia, ib = i[keep], j[keep], ia[keep], ib[keep]
    gap, over, _ = pair_gaps(kinds[i], ev.center[ia[:, 0]], ev.radius[ia[:, 0]],
                             (ev.center[ia[:, 1]], ev.radius[ia[:, 1]]), kinds[j], ev.center[ib[:, 0]],
                             ev.radius[ib[:, 0]], (ev.center[ib[:, 1]], ev.radius[ib[:, 1]]))
    kind = kinds[i] + kinds[j]
    counts = {name: int(np.sum(over & (kind == k))) for k, name in enumerate(KINDS)}
    near = ~over & (gap <= margin)
    return counts, (float(gap[near].min()) if near.any() else None)


def _crossing(kind: str) -> Lattice:
    """Lattices built to overlap: crossing face diagonals (beam–beam), a ball sitting on a strut
    (ball–beam), fat balls of next neighbours (ball–ball), under several steady similarities."""
    lat = Lattice()
    a = lat.add_node([0, 0, 0], 0.12)
    b = lat.add_node([0.5, 0.08, 0.0], 0.07)  # close to the x strut of its own group: overlaps it
    lat.add_node([0.5, 0.5, 0.5], 0.3)  # two lone balls overlapping each other (ball–ball)
    lat.add_node([0.5, 0.5, 0.95], 0.2)
    lat.add_beam(a, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 0, 0, 1)
    lat.add_beam(a, a, 1, 1, 0)  # the two face diagonals cross at the face centre
    lat.add_beam(a, a, -1, 1, 0)
    lat.add_beam(b, a, 0, 1, 0)
    if kind == "regular":
        lat.set_u(3, Translation([1, 0, 0]))
        lat.set_v(4, Translation([0, 1, 0]))
        lat.set_w(3, Translation([0, 0, 1]))
    elif kind == "steady":
        lat.set_u(3, Rotation(0.05, [0, 1, 0], [0, 0, -10]))
        lat.set_v(3, Screw(0.04, [1, 0, 0], [0, -8, 0], 1.0))
        lat.set_w(4, Scaling(1.04, [0.3, 0.2, -15]))
    else:  # commuting: rotation and screw about one axis, a translation along it
        lat.set_u(3, Translation([1, 0, 0]))
        lat.set_v(4, Rotation(0.09, [1, 0, 0], [0, -8, 0]))
        lat.set_w(3, Screw(0.05, [1, 0, 0], [0, -8, 0], 1.0))
    return lat


@pytest.mark.parametrize("kind", ["regular", "steady", "commuting"])
@pytest.mark.parametrize("path", ["steady", "explicit"])
def test_unclean_pairs_vs_all_pairs(kind, path):
    lat = _crossing(kind)
    margin = 0.4
    want, gap = _brute(lat.evaluate(), margin)
    got = unclean_pairs(lat, margin=margin, path=path)
    assert got["path"].startswith(path)
    assert got["pairs"] == want
    assert want["beam_beam"] and want["ball_beam"] and want["ball_ball"] and not got["clean"]
    assert (got["min_gap"] is None) == (gap is None)
    if gap is not None:
        assert got["min_gap"] == pytest.approx(gap, rel=1e-9, abs=1e-12)
    assert got["worst"] and all(w["depth"] > 0 for w in got["worst"])


def test_filtered_and_region_use_the_kept_elements():
    lat = _crossing("steady")
    lat.set_filter(Stencil(np.array([[[1, 0], [1, 1]], [[0, 1], [1, 1]]])))
    for region in (None, "1:3,0:3,1:4"):
        ev = lat.evaluate(region)
        want, gap = _brute(ev, 0.3)
        got = unclean_pairs(lat, ev, margin=0.3)
        assert got["pairs"] == want and got["path"] == "explicit"
        assert got["min_gap"] == (pytest.approx(gap, rel=1e-9) if gap is not None else None)


@pytest.mark.parametrize("name", ["cubic", "bcc", "fcc", "octet", "kagome", "becots_triangle", "fig6_3"])
def test_clean_presets(name):
    lat = load_lattice(name)
    got = unclean_pairs(lat)
    assert got["clean"], got["worst"][:3]
    assert unclean_pairs(lat, path="explicit")["pairs"] == got["pairs"]
    if lat.node_count() + lat.beam_count() <= 1200:  # small enough for all pairs
        assert _brute(lat.evaluate(), 0.0)[0] == got["pairs"]


def _cylinder(nv: int, turns: float) -> Lattice:
    """A cylindrical lattice (radial U translation, angular V rotation, axial W translation: V and
    W similar), its V row spanning ``turns`` full turns: past one turn it overlaps itself."""
    lat = Lattice()
    angle = 2 * np.pi * turns / nv
    a = lat.add_node([2.0, 0, 0], 0.12)
    b = lat.add_node([2.3, 0.4, 0.3], 0.08)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.add_beam(b, a, 0, 1, 1)
    lat.add_beam(b, a, 1, 0, -1)
    lat.set_u(3, Translation([0.6, 0, 0]))
    lat.set_v(nv, Rotation(angle, [0, 0, 1], [0, 0, 0]))
    lat.set_w(4, Translation([0, 0, 0.6]))
    return lat


@pytest.mark.parametrize("turns", [11 / 12, 1.3, 1.4])
def test_curved_lattice_wrapping_around_vs_all_pairs(turns):
    """A row of rotations closing its circle (the last group next to the first, 11 indices apart)
    and rows overlapping themselves (1.3, 1.4 turns): the steady path meets the pairs of far indices."""
    lat = _cylinder(12, turns)
    want, gap = _brute(lat.evaluate(), 0.3)
    got = unclean_pairs(lat, margin=0.3, path="steady")
    assert got["path"] == "steady (VW similar)" and got["pairs"] == want
    assert turns < 1 or want["ball_beam"] > 0  # past one turn, balls sit on beams of the next turn
    assert got["min_gap"] == (pytest.approx(gap, rel=1e-9) if gap is not None else None)


@pytest.mark.parametrize("split", [None, 23])
def test_candidate_pairs_count_the_grid_before_pairing(split):
    """The count is exact against the grid's cells (every two boxes sharing a cell; with a split,
    a box of each set), and bounds the pairs ``grid_pairs`` yields."""
    from ple.queries.overlaps import _cell_entries, _grid

    rng = np.random.default_rng(5)
    lo = rng.uniform(0, 4, (60, 3))
    hi = lo + rng.uniform(0.1, 1.5, (60, 3))
    count = candidate_pairs(lo, hi, 0.2, split)
    _, _, first, span, dims = _grid(lo, hi, 0.2)
    key, owner = _cell_entries(first, span, dims, np.arange(60))
    cells: dict = {}
    for k, o in zip(key.tolist(), owner.tolist()):
        cells.setdefault(k, []).append(o)
    want = sum(len(m) * (len(m) - 1) // 2 if split is None else sum(o < split for o in m) * sum(o >= split for o in m)
               for m in cells.values())
    assert count == want
    assert sum(len(i) for i, _ in grid_pairs(lo, hi, 0.2, split)) <= count


def test_a_check_of_elements_overlapping_everything_is_refused_before_testing():
    lat = Lattice()
    a = lat.add_node((0, 0, 0), 2.5)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    for d, v in zip("uvw", np.eye(3)):
        getattr(lat, f"set_{d}")(5, Translation(v))
    ev = lat.evaluate()
    with pytest.raises(PleError, match=r"candidate pairs .* --max-pairs"):
        unclean_pairs(lat, ev, max_pairs=1e4)
    with pytest.raises(PleError, match=r"candidate pairs .* --max-pairs"):
        unclean_pairs(lat, path="steady", max_pairs=1e3)
    assert not unclean_pairs(lat, ev)["clean"]  # within the default limit
    assert unclean_pairs(lat, ev, first=True, max_pairs=1)["clean"] is False  # the quick look is bounded anyway


def test_beam_pairs_certified_overlapping_agree_with_the_golden_section():
    """Beam pairs whose axis balls overlap skip the gap search: gaps and overlap flags equal the
    exact search's (``beam_beam_gap`` of the beams, and of the beams shrunk by the tolerance)."""
    from ple.queries.overlaps import CLEAN_TOL

    rng = np.random.default_rng(11)
    n = 4000
    a1, b1, a2, b2 = (rng.uniform(0, 2, (n, 3)) for _ in range(4))
    ra1, rb1, ra2, rb2 = (rng.uniform(0.01, 0.4, n) for _ in range(4))
    ones = np.ones(n, np.int64)
    gap, over, _ = pair_gaps(ones, a1, ra1, (b1, rb1), ones, a2, ra2, (b2, rb2))
    tol = CLEAN_TOL * np.max([ra1, rb1, ra2, rb2], axis=0)
    want_gap = beam_beam_gap(a1, ra1, b1, rb1, a2, ra2, b2, rb2)
    want_over = (want_gap <= 0) & (beam_beam_gap(a1, ra1 - tol, b1, rb1 - tol, a2, ra2 - tol, b2, rb2 - tol) <= 0)
    assert 0.2 < over.mean() < 0.9  # both kinds present
    np.testing.assert_array_equal(over, want_over)
    np.testing.assert_allclose(gap, want_gap, atol=1e-12)
