"""The Möbius RangeFinder (``ple.queries.mobius_rangefinder``; thesis §11.2.1, §11.3, §11.4) against
brute force: every hit list of ``biq.query`` equals the naive path's (every element tested) on
loxodromic 1-patterns, TMI slabs and similarity-placed Möbius lattices, for uniform, touching,
point (PMC) and inversion-centre queries; lattices without a pre-image say why and go naive."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ple import Lattice, Pt
from ple.algebra.mobius import Cline, Mobius
from ple.algebra.similarity import Swirl, commute
from ple.algebra.vectors import Vec
from ple.errors import PleError
from ple.model.mobius import TMIMap, mobius_lattice
from ple.program.sources import load_lattice
from ple.queries import biq, mobius_rangefinder

PRESETS = Path(__file__).parents[2] / "presets"


def _cell(radius=0.08, offsets=((1, 0, 0),)) -> Lattice:
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), radius)
    b = cell.add_node(Pt(0.45, 0.3, 0.05), radius * 0.6)
    cell.add_beam(a, b)
    for off in offsets:
        cell.add_beam(a, a, *off)
        cell.add_beam(b, a, *off)
    return cell


def loxodrome(rng, count: int, angle: float | None = None) -> Lattice:
    """A Möbius 1-pattern whose U is a swirl seen through a circle inversion (§11.2.1)."""
    f = complex(*rng.normal(size=2))
    angle = rng.uniform(0.05, 0.4) if angle is None else angle
    s = Swirl(angle, Vec(0, 0, 1), Pt(f.real, f.imag, 0), rng.uniform(0.9, 0.99))
    inv = Cline.circle(complex(*rng.normal(size=2) * 3), rng.uniform(1, 3))
    g = Mobius.from_coefficients(1, complex(*rng.normal(size=2)) * 0.3, 0.02, 1)
    return mobius_lattice(_cell(offsets=((1, 0, 0), (2, 0, 0))), Mobius.conjugated(s, inv), None, None,
                          (count, 1, 1), g)


def tmi(rng, n=(12, 9)) -> Lattice:
    """A TMI slab of five perturbed points (§11.4.2) whose balls all map to balls."""
    base = np.array([0, 4, 0.5 + 4j, 4.5 + 5j, 2.2 - 0.6j])
    offsets = ((1, 0, 0), (0, 1, 0), (1, 1, 0), (1, -1, 0))
    while True:
        pts = base + (rng.normal(size=5) + 1j * rng.normal(size=5)) * 0.3
        lat = TMIMap.from_five(*pts).lattice(_cell(0.1, offsets), n)
        try:
            lat.evaluate()
        except PleError:  # a ball around a pole of some group's map
            continue
        return lat


def _queries(lat: Lattice, rng, count: int = 300):
    """Uniform balls; balls that reach a node by 1e-11 of the coordinates' size or miss it by as
    much; points that far inside a node's sphere; the inversion centre and a ball around it.
    (Closer than that, touching is decided by rounding: a node's bits depend on the batch it
    is evaluated in, for the naive path too.)"""
    lo, hi = lat.bounds()
    c = rng.uniform(lo, hi, (count, 3))
    r = rng.uniform(0, 2, count) * lat.mean_radius()
    ev = lat.evaluate()
    pick = rng.integers(0, len(ev.radius), count // 3)
    d = rng.normal(size=(len(pick), 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    eps = 1e-11 * (np.abs(ev.center[pick]).max(axis=1) + ev.radius[pick] + 1)
    far = ev.center[pick] + d * (ev.radius[pick] + rng.uniform(0, 1, len(pick)))[:, None]
    gap = np.linalg.norm(far - ev.center[pick], axis=1) - ev.radius[pick]
    on = ev.center[pick] + d * (ev.radius[pick] - eps)[:, None]
    c = np.concatenate([c, far, far, on])
    r = np.concatenate([r, gap + eps, gap - eps, np.zeros(len(on))])
    pl = mobius_rangefinder.cached_plan(lat)
    if pl.center is not None:
        c = np.concatenate([c, pl.center[None], pl.center[None] + 0.01])
        r = np.concatenate([r, [0.0, 0.5]])
    return c, r


def _same_as_naive(lat: Lattice, c, r) -> list:
    fast = biq.query(lat, c, r)
    slow = biq.query(lat, c, r, method="naive")
    assert len(fast) == len(slow) == len(c)
    for n, (a, b) in enumerate(zip(fast, slow)):
        assert np.array_equal(a.nodes, b.nodes), n
        assert np.array_equal(a.beams, b.beams), n
    assert np.array_equal(biq.pmc(lat, c), biq.naive_any(lat, c, np.zeros(len(c))))
    return fast


@pytest.mark.parametrize("seed", range(6))
def test_loxodromic_rows_equal_brute_force(seed):
    rng = np.random.default_rng(seed)
    lat = loxodrome(rng, int(rng.integers(20, 200)))
    pl = mobius_rangefinder.cached_plan(lat)
    assert pl.pre is not None and pl.center is not None
    fast = _same_as_naive(lat, *_queries(lat, rng))
    assert fast[0].path.startswith("mobius")
    assert sum(len(x.nodes) + len(x.beams) for x in fast) > 0


@pytest.mark.parametrize("seed", range(4))
def test_tmi_slabs_equal_brute_force(seed):
    rng = np.random.default_rng(10 + seed)
    lat = tmi(rng)
    fast = _same_as_naive(lat, *_queries(lat, rng))
    assert fast[0].path.startswith("mobius")


def test_beams_bounded_through_the_inversion_centre():
    """Half-turn steps: consecutive balls lie across F, so some beam bounds contain F (§11.3) and
    are candidates of every query; the hits still equal brute force."""
    rng = np.random.default_rng(7)
    lat = loxodrome(rng, 60, angle=2.9)
    pl = mobius_rangefinder.cached_plan(lat)
    assert len(pl.always) > 0
    _same_as_naive(lat, *_queries(lat, rng))


def test_pre_image_nodes_are_the_inverted_nodes():
    """§11.2.1: R(W^k V^j U^i G B) = S_W^k S_V^j S_U^i (R G B), checked on every node."""
    rng = np.random.default_rng(3)
    lat = tmi(rng, (6, 5))
    pl = mobius_rangefinder.cached_plan(lat)
    ev = lat.evaluate()
    want_c, want_r, den = mobius_rangefinder.invert_balls(pl.center, pl.rho2, ev.center, ev.radius)
    assert np.all(den > 0)
    got_c, got_r = pl.pre.node_balls(ev.node_index)
    scale = np.linalg.norm(want_c, axis=1) + want_r
    assert np.all(np.linalg.norm(got_c - want_c, axis=1) <= 1e-9 * scale)
    assert np.all(np.abs(got_r - want_r) <= 1e-9 * scale)
    assert commute(pl.pre.U, pl.pre.V)


def test_similarity_placed_mobius_rows_need_no_inversion():
    lat = load_lattice(str(PRESETS / "mobius_slab.py"), {"nu": 30, "nv": 1})  # its U fixes ∞
    pl = mobius_rangefinder.cached_plan(lat)
    assert pl.pre is not None and pl.center is None
    _same_as_naive(lat, *_queries(lat, np.random.default_rng(4)))


def test_non_commuting_frames_say_why_and_go_naive():
    lat = load_lattice(str(PRESETS / "mobius_slab.py"), {"nu": 5, "nv": 4})
    rng = np.random.default_rng(5)
    fast = _same_as_naive(lat, *_queries(lat, rng, 30))
    assert fast[0].path == "naive (group map: U, V, W do not commute (§11.3))"


def test_filtered_mobius_lattice_keeps_only_kept_hits():
    from ple.filters.stencil import Stencil

    lat = tmi(np.random.default_rng(8), (6, 6))
    kept = lat.with_filter(Stencil(np.indices((2, 2, 1)).sum(axis=0) % 2))
    c, r = _queries(lat, np.random.default_rng(9), 120)
    for a, b in zip(biq.query(kept, c, r), biq.query(kept, c, r, method="naive")):
        assert np.array_equal(a.nodes, b.nodes) and np.array_equal(a.beams, b.beams)
        assert np.all(a.nodes[:, :3].sum(axis=1) % 2 == 1)


def test_identity_similarity_of_a_single_group():
    lat = mobius_lattice(_cell(), Mobius.from_coefficients(1, 0.1, 0.01, 1), None, None, (1, 1, 1))
    assert mobius_rangefinder.cached_plan(lat).reason == "one group"
