"""ACHoCC junctions (CHoCC paper §5): the inflated radius r⁺ puts every contact circle on its
beam's cone, the contact circles of a clean hub are disjoint, and a hub's exit distance and
signed distance agree with the exact cone-beam distance of ``algebra.elements``."""

from __future__ import annotations

import numpy as np
import pytest
from ple.algebra.elements import beam_distance
from ple.algebra.vectors import perpendicular_frames, unit_rows
from ple.meshing.achocc import contact_circles, hub_geometry, inflated_radius


def _hub(rng, n):
    """A clean hub: n well-spread beam directions (a Fibonacci sphere, randomly turned and
    jittered), beams several radii long."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    spread = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    dirs = unit_rows(spread @ q.T + 0.05 * rng.normal(size=(n, 3)))
    lengths = 2.0 + rng.random(n)
    return 0.2, dirs, 0.1 + 0.1 * rng.random(n), lengths


def _circle_points(r_plus, dirs, x, y, k=24):
    e1, e2 = perpendicular_frames(dirs)
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    return (dirs[:, None] * x[:, None, None] + (np.cos(t)[None, :, None] * e1[:, None]
            + np.sin(t)[None, :, None] * e2[:, None]) * y[:, None, None])


@pytest.mark.parametrize("n", [2, 3, 4, 6])
def test_contact_circles_lie_on_their_cones_at_r_plus(rng, n):
    radius, dirs, other, lengths = _hub(rng, n)
    r_plus = inflated_radius(radius, dirs, other, lengths)
    assert r_plus >= radius
    _, x, y = contact_circles(radius, r_plus, dirs, other, lengths)  # strict: a clean hub
    pts = _circle_points(r_plus, dirs, x, y)  # (S, k, 3)
    assert np.allclose(np.linalg.norm(pts, axis=2), r_plus, rtol=1e-9)  # on the sphere S⁺
    for b in range(n):  # ... and on the surface of beam b (independent distance formula)
        d = beam_distance(pts[b], np.zeros(3), radius, dirs[b] * lengths[b], other[b])
        assert np.allclose(d, 0.0, atol=1e-9)


def test_two_beams_meet_exactly_at_r_plus():
    """Two equal beams at 90°: their profiles cross at r⁺ = r·√2 / cos(φ) geometry, i.e. the
    largest radius where both cones still meet; there the two contact circles touch."""
    radius, dirs = 0.3, np.array([[1.0, 0, 0], [0, 1.0, 0]])
    other, lengths = np.array([0.3, 0.3]), np.array([2.0, 2.0])
    r_plus = inflated_radius(radius, dirs, other, lengths)
    assert np.isclose(r_plus, radius * np.sqrt(2))  # capsules: the profile lines y = r meet at (r, r)
    half, _, _ = contact_circles(radius, r_plus, dirs, other, lengths)
    assert np.isclose(half.sum(), np.pi / 2)  # the two cones' half-angles fill the 90° between the axes


@pytest.mark.parametrize("n", [1, 3, 5])
def test_hub_signed_distance_is_the_union_of_its_beams(rng, n):
    radius, dirs, other, lengths = _hub(rng, n)
    hub = hub_geometry(radius, dirs, other, lengths)
    p = (rng.random((500, 3)) - 0.5) * 1.0
    want = np.min([beam_distance(p, np.zeros(3), radius, dirs[k] * lengths[k], other[k]) for k in range(n)], axis=0)
    assert np.allclose(hub.signed_distance(p), want, atol=1e-9)
    u = unit_rows(rng.normal(size=(200, 3)))
    t = hub.exit_distance(u)  # the ray leaves the union exactly there: distance 0 at the exit point
    exits = u * t[:, None]
    d = np.min([beam_distance(exits, np.zeros(3), radius, dirs[k] * lengths[k], other[k]) for k in range(n)], axis=0)
    assert np.allclose(d, 0.0, atol=1e-9)


def test_batched_exit_distances_are_each_hubs_dense_maximum(rng):
    """``exit_distances`` evaluates the closed forms only for rays inside a beam's cap: the
    same values, bit for bit, as every (ray, beam) pair evaluated and the largest taken, for
    hubs with narrowing, widening and parallel beams; and each exit lies on the union."""
    from ple.meshing.achocc import beam_profile, exit_distances

    hubs = [_hub(rng, 5) for _ in range(6)]
    radius = np.array([h[0] for h in hubs]) * rng.uniform(0.8, 1.2, 6)
    dirs = np.stack([h[1] for h in hubs])
    other = np.stack([h[2] for h in hubs]) * rng.uniform(0.5, 1.5, (6, 5))
    lengths = np.stack([h[3] for h in hubs])
    u = unit_rows(rng.normal(size=(6 * 400, 3))).reshape(6, 400, 3)
    got = exit_distances(u, radius, dirs, other, lengths)
    r = radius[:, None, None]
    sphi, cphi = beam_profile(radius[:, None], other, lengths)
    sphi, cphi, ln, ro = sphi[:, None], cphi[:, None], lengths[:, None], other[:, None]
    cu = np.clip(np.einsum("hvi,hsi->hvs", u, dirs), -1, 1)  # every pair (H, V, S)
    den = sphi * cu + cphi * np.sqrt(1 - cu**2)
    t_cone = np.where(den > 0, r / np.where(den > 0, den, 1.0), np.inf)
    t_ball = ln * cu + np.sqrt(np.maximum(ln**2 * cu**2 - ln**2 + ro**2, 0))
    t_k = np.where(cu <= sphi, r, np.where(t_cone * cu <= ln + ro * sphi, t_cone, t_ball))
    assert np.array_equal(got, np.maximum(r[..., 0], t_k.max(axis=-1)))
    for h in range(6):
        exits = u[h] * got[h][:, None]
        d = np.min([beam_distance(exits, np.zeros(3), radius[h], dirs[h, k] * lengths[h, k], other[h, k])
                    for k in range(5)], axis=0)
        assert np.allclose(d, 0.0, atol=1e-9)
    assert np.array_equal(exit_distances(u, radius, dirs[:, :0], other[:, :0], lengths[:, :0]),
                          np.broadcast_to(radius[:, None], (6, 400)))
