"""Exact element tests against brute force: a cone-beam is the union of the balls
((1-t) a + t b, (1-t) ra + t rb), t in [0, 1], so its distance is a 1D minimum."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple.algebra.elements import ball_ball_interfere, ball_beam_interfere, beam_distance, enclosing_ball

T = np.linspace(0.0, 1.0, 8001)


def brute_distance(p, a, ra, b, rb):
    """min over t of |p - c(t)| - r(t): the exact distance outside, <= 0 inside."""
    c = (1 - T)[:, None] * a + T[:, None] * b
    r = (1 - T) * ra + T * rb
    return (np.linalg.norm(p[:, None] - c[None], axis=2) - r[None]).min(axis=1)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_beam_distance_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=3)
    b = a + rng.normal(size=3) * rng.uniform(0.0, 2.0)
    ra, rb = rng.uniform(0.05, 1.2, 2)
    p = a + rng.normal(size=(64, 3)) * 2
    d = beam_distance(p, a, ra, b, rb)
    bf = brute_distance(p, a, ra, b, rb)
    outside = bf > 1e-6
    # exterior: exact distance (sampling of t is accurate to ~1e-7 here)
    assert np.allclose(d[outside], bf[outside], atol=2e-6)
    assert np.array_equal(d <= 0, bf <= 0)


def test_inside_is_negative_distance_to_the_surface():
    # capsule along x of radius 1 and length 4: inside, distance to the boundary is known
    a, b = np.zeros(3), np.array([4.0, 0, 0])
    p = np.array([[2.0, 0.3, 0], [0.0, 0, 0], [-0.5, 0, 0], [4.2, 0.1, 0]])
    assert np.allclose(beam_distance(p, a, 1.0, b, 1.0), [-0.7, -1.0, -0.5, np.hypot(0.2, 0.1) - 1])


def test_one_ball_containing_the_other_is_that_ball():
    a, b = np.zeros(3), np.array([0.3, 0, 0])
    p = np.random.default_rng(1).normal(size=(50, 3)) * 3
    assert np.allclose(beam_distance(p, a, 2.0, b, 0.5), np.linalg.norm(p - a, axis=1) - 2.0)
    assert np.allclose(beam_distance(p, b, 0.5, a, 2.0), np.linalg.norm(p - a, axis=1) - 2.0)
    # coincident centres
    assert np.allclose(beam_distance(p, a, 1.0, a, 0.5), np.linalg.norm(p, axis=1) - 1.0)


def test_equal_radii_capsule_side():
    a, b = np.zeros(3), np.array([0, 0, 5.0])
    p = np.array([[3.0, 0, 2.5], [0, -2, 1]])
    assert np.allclose(beam_distance(p, a, 0.5, b, 0.5), [2.5, 1.5])


def test_near_tangent_interference():
    rng = np.random.default_rng(3)
    for _ in range(200):
        a = rng.normal(size=3)
        b = a + rng.normal(size=3)
        ra, rb = rng.uniform(0.1, 0.5, 2)
        q = a + rng.normal(size=3) * 3
        d = float(beam_distance(q, a, ra, b, rb))
        if d <= 1e-3:
            continue
        assert ball_beam_interfere(q, d * (1 + 1e-9), a, ra, b, rb)
        assert not ball_beam_interfere(q, d * (1 - 1e-6), a, ra, b, rb)
    c1, c2 = np.zeros(3), np.array([1.0, 0, 0])
    assert ball_ball_interfere(c1, 0.4, c2, 0.6)  # touching counts
    assert not ball_ball_interfere(c1, 0.4, c2, 0.6 - 1e-9)


def test_vectorized_shapes_broadcast():
    q = np.zeros((5, 1, 3))
    a = np.random.default_rng(0).normal(size=(1, 7, 3))
    out = ball_beam_interfere(q, np.ones((5, 1)), a, 0.1, a + 1, 0.2)
    assert out.shape == (5, 7)


def test_enclosing_ball_contains_the_beam():
    rng = np.random.default_rng(5)
    for _ in range(50):
        a, b = rng.normal(size=3), rng.normal(size=3)
        ra, rb = rng.uniform(0.05, 1, 2)
        c, r = enclosing_ball(a, ra, b, rb)
        # every ball of the hull lies inside: |c(t) - c| + r(t) <= r
        ct = (1 - T)[:, None] * a + T[:, None] * b
        rt = (1 - T) * ra + T * rb
        assert np.all(np.linalg.norm(ct - c, axis=1) + rt <= r + 1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_segment_distance_matches_dense_sampling_with_points_in_either_place(seed):
    """Segment–segment distance, either segment possibly a point (a hub centre), vs the minimum
    over dense samples of both segments; and symmetric in the two segments."""
    from ple.algebra.elements import segment_distance

    rng = np.random.default_rng(seed)
    k = 200
    p1, q1, p2, q2 = (rng.normal(size=(k, 3)) for _ in range(4))
    q1[: k // 4] = p1[: k // 4]  # first a point
    q2[k // 4: k // 2] = p2[k // 4: k // 2]  # second a point
    q1[k // 2: k // 2 + 10], q2[k // 2: k // 2 + 10] = p1[k // 2: k // 2 + 10], p2[k // 2: k // 2 + 10]  # both
    s = np.linspace(0, 1, 401)
    a = p1[:, None] + s[None, :, None] * (q1 - p1)[:, None]
    b = p2[:, None] + s[None, :, None] * (q2 - p2)[:, None]
    brute = np.empty(k)
    for i in range(k):  # pair by pair: all (k, 401, 401, 3) differences at once would take 0.8 GB
        d = a[i][:, None] - b[i][None, :]
        brute[i] = np.sqrt(np.einsum("stx,stx->st", d, d).min())
    step = (np.linalg.norm(q1 - p1, axis=1) + np.linalg.norm(q2 - p2, axis=1)) / 400
    d = segment_distance(p1, q1, p2, q2)
    assert np.all(d <= brute + 1e-12) and np.all(brute - d <= step + 1e-12)
    assert np.allclose(d, segment_distance(p2, q2, p1, q1), atol=1e-12)
