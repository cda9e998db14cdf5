"""The RangeFinder of one steady row (thesis §7.1): the candidate range of a query ball holds every
index whose ball it touches, checked against brute force over the row; and the whole-lattice
RangeFinder returns exactly the naive hits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple import Lattice, Pt, Rotation, Scaling, Screw, Swirl, Translation, Vec
from ple.algebra.elements import ball_ball_interfere
from ple.queries.biq import query
from ple.queries.rangefinder import lattice_hits, row_candidates

SIMS = [Translation(Vec(1.0, 0.2, 0)), Rotation(0.3, Vec(0, 0, 1), Pt(2, 0, 0)),
        Scaling(1.07, Pt(-5, 1, 0)), Screw(0.25, Vec(0, 1, 1), Pt(1, 0, 0), 0.4),
        Swirl(0.2, Vec(1, 0, 1), Pt(0, -3, 0), 0.96)]


def brute_row(s, count, c0, r0, qc, qr) -> np.ndarray:
    """Indices k < count whose ball S**k (c0, r0) interferes with the query (every k computed)."""
    ks = np.arange(count)
    centers = np.array([(s ** int(k)).apply_points(c0[None])[0] for k in ks])
    radii = np.array([r0 * s.factor ** int(k) for k in ks])
    return ks[ball_ball_interfere(centers, radii, qc[None], qr)]


@settings(max_examples=60, deadline=None)
@given(sim=st.sampled_from(range(len(SIMS))), count=st.integers(1, 40),
       q=st.lists(st.floats(-8, 8), min_size=3, max_size=3), qr=st.floats(0.0, 3.0))
def test_row_candidates_cover_every_hit(sim, count, q, qr):
    s, c0, r0 = SIMS[sim], np.array([0.5, 0.0, 0.2]), 0.3
    qc = np.array(q)
    lo, hi = row_candidates(s, count, c0, r0, qc[None], np.array([qr]))
    hits = brute_row(s, count, c0, r0, qc, qr)
    if len(hits):
        assert lo[0] <= hits.min() and hits.max() <= hi[0], (lo, hi, hits)


def test_row_candidates_of_a_translation_are_tight():
    """Translation rows (the O(1) path): the range is exactly the brute-force hit range."""
    s = Translation(Vec(1.0, 0, 0))
    qc, qr = np.array([[4.2, 0.0, 0.0]]), np.array([1.0])
    lo, hi = row_candidates(s, 20, np.zeros(3), 0.25, qc, qr)
    hits = brute_row(s, 20, np.zeros(3), 0.25, qc[0], qr[0])
    assert (lo[0], hi[0]) == (hits.min(), hits.max()) == (3, 5)


@pytest.mark.parametrize("u, v", [(0, 1), (1, 0), (2, 3), (4, 0)])
def test_lattice_hits_equal_the_naive_path(u, v, rng):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.15)
    b = lat.add_node(Pt(0.4, 0.3, 0.1), 0.1)
    lat.add_beam(a, b)
    lat.add_beam(b, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    lat.set_u(7, SIMS[u])
    lat.set_v(5, SIMS[v])
    lo, hi = lat.bounds()
    centers = lo + (hi - lo) * rng.random((40, 3))
    radii = rng.random(40) * 0.4
    fast = query(lat, centers, radii, method="rangefinder")
    naive = query(lat, centers, radii, method="naive")
    for f, n in zip(fast, naive):
        assert np.array_equal(f.nodes, n.nodes) and np.array_equal(f.beams, n.beams)
    nh, bh, path = lattice_hits(lat, centers, radii)
    assert path in ("1", "u", "uv", "naive") and len(nh) == sum(len(n.nodes) for n in naive)
