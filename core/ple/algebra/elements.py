"""Exact element tests: ball–ball, ball–cone-beam, signed distance to a cone-beam (thesis §2.1).

A cone-beam is the convex hull of two balls (a, ra) and (b, rb). In the plane through the
axis a→b it is bounded by the two circles and by their outer common tangents; with
``x`` measured along the axis from a and ``y`` the distance from the axis, the tangent
line has unit normal ``n = (-s, c)`` where ``s = (ra - rb) / |ab|`` and ``c = sqrt(1 - s²)``.
A point whose coordinate along the tangent direction ``t = (c, s)`` falls before the
contact point on ball a is closest to ball a, after the contact point on ball b closest to
ball b, otherwise closest to the tangent line. Every function is vectorized: arguments
broadcast against each other (centres (..., 3), radii (...)).
"""

from __future__ import annotations

import numpy as np

# Relative slack for interference: touching counts as interfering, and values within this
# fraction of the sizes involved are treated as touching (near-tangent queries are stable).
TOUCH_TOL = 1e-12


def ball_ball_interfere(c1, r1, c2, r2) -> np.ndarray:
    """Do closed balls (c1, r1) and (c2, r2) intersect? bool array of the broadcast shape."""
    d2 = np.sum((np.asarray(c1, float) - np.asarray(c2, float)) ** 2, axis=-1)
    rr = np.asarray(r1, float) + np.asarray(r2, float)
    return d2 <= rr * rr * (1 + TOUCH_TOL) + TOUCH_TOL * TOUCH_TOL


def beam_distance(p, a, ra, b, rb) -> np.ndarray:
    """Signed distance from points ``p`` to cone-beams hull(ball(a, ra), ball(b, rb)).

    Negative inside. Special cases: one ball containing the other (|ab| + r_small <= r_big,
    the hull is the bigger ball) and coincident centres; equal radii give a capsule
    (s = 0), which the general formula covers.
    """
    p, a, b = (np.asarray(x, float) for x in (p, a, b))
    ra, rb = np.asarray(ra, float), np.asarray(rb, float)
    ab = b - a
    length = np.sqrt(np.sum(ab * ab, axis=-1))
    safe = np.where(length > 0, length, 1.0)
    e = ab / safe[..., None]
    ap = p - a
    x = np.sum(ap * e, axis=-1)
    y = np.sqrt(np.maximum(np.sum(ap * ap, axis=-1) - x * x, 0.0))
    s = np.clip((ra - rb) / safe, -1.0, 1.0)
    c = np.sqrt(1.0 - s * s)
    u = c * x - s * y  # position along the tangent direction; contact points at 0 and c·|ab|
    da = np.sqrt(x * x + y * y) - ra
    db = np.sqrt((x - length) ** 2 + y * y) - rb
    side = s * x + c * y - ra
    dist = np.where(u <= 0, da, np.where(u >= c * length, db, side))
    # special case: one ball contains the other (or zero length): the hull is the bigger ball
    a_big = length + rb <= ra
    b_big = length + ra <= rb
    dist = np.where(a_big, da, np.where(b_big, db, dist))
    return dist


def ball_beam_interfere(q, rq, a, ra, b, rb) -> np.ndarray:
    """Does ball (q, rq) intersect cone-beam hull(ball(a, ra), ball(b, rb))? bool array."""
    d = beam_distance(q, a, ra, b, rb)
    rq = np.asarray(rq, float)
    scale = np.maximum(np.maximum(np.asarray(ra, float), np.asarray(rb, float)), rq)
    return d <= rq + TOUCH_TOL * scale


def point_in_ball(p, c, r) -> np.ndarray:
    """Point membership in closed balls (PMC of a ball)."""
    return ball_ball_interfere(p, 0.0, c, r)


def enclosing_ball(a, ra, b, rb) -> tuple[np.ndarray, np.ndarray]:
    """Smallest ball containing hull(ball(a, ra), ball(b, rb)): centres (..., 3), radii (...)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ra, rb = np.asarray(ra, float), np.asarray(rb, float)
    ab = b - a
    length = np.sqrt(np.sum(ab * ab, axis=-1))
    safe = np.where(length > 0, length, 1.0)
    e = ab / safe[..., None]
    radius = (length + ra + rb) / 2
    center = a + e * (radius - ra)[..., None]
    a_big = length + rb <= ra
    b_big = length + ra <= rb
    center = np.where(a_big[..., None], a, np.where(b_big[..., None], b, center))
    radius = np.where(a_big, ra, np.where(b_big, rb, radius))
    return center, radius


GAP_ITERATIONS = 64  # golden-section steps of ``beam_beam_gap`` (interval 0.618^64 ≈ 4e-14 of the axis)


def beam_beam_gap(a1, ra1, b1, rb1, a2, ra2, b2, rb2) -> np.ndarray:
    """Distance between cone-beams hull(ball(a1, ra1), ball(b1, rb1)) and hull(ball(a2, ra2),
    ball(b2, rb2)), 0 where they intersect (vectorized over leading axes).

    Beam 1 is the union of the balls (a1 + t (b1 − a1), ra1 + t (rb1 − ra1)), t in [0, 1], so the
    gap is min_t max(d₂(P(t)) − r(t), 0) with d₂ the signed distance to beam 2 (``beam_distance``:
    exact outside, negative inside). That function is convex in t (a convex distance along a
    segment minus a linear radius, clipped at 0), so a golden-section search finds its minimum."""
    a1, b1, a2, b2 = (np.asarray(x, float) for x in (a1, b1, a2, b2))
    ra1, rb1 = np.asarray(ra1, float), np.asarray(rb1, float)

    def f(t):
        p = a1 + t[..., None] * (b1 - a1)
        return np.maximum(beam_distance(p, a2, ra2, b2, rb2) - (ra1 + t * (rb1 - ra1)), 0.0)

    shape = np.broadcast_shapes(a1.shape[:-1], b1.shape[:-1], a2.shape[:-1], b2.shape[:-1], ra1.shape, rb1.shape,
                                np.shape(ra2), np.shape(rb2))
    g = (np.sqrt(5.0) - 1) / 2
    lo, hi = np.zeros(shape), np.ones(shape)
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(GAP_ITERATIONS):
        left = f1 <= f2  # the minimum lies in [lo, x2], else in [x1, hi]
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
        f1, f2 = f(x1), f(x2)
    return np.minimum.reduce([f1, f2, f(np.zeros(shape)), f(np.ones(shape))])


def segment_distance(p1, q1, p2, q2) -> np.ndarray:
    """Distance between segments [p1, q1] and [p2, q2] (vectorized), by their closest points
    (``segment_closest``)."""
    p1, q1, p2, q2 = (np.asarray(x, float) for x in (p1, q1, p2, q2))
    s, t = segment_closest(p1, q1, p2, q2)
    diff = p1 + s[..., None] * (q1 - p1) - (p2 + t[..., None] * (q2 - p2))
    return np.sqrt(np.sum(diff * diff, axis=-1))


def segment_closest(p1, q1, p2, q2) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (s, t) in [0, 1] of the closest points p1 + s (q1 − p1) and p2 + t (q2 − p2) of
    segments [p1, q1] and [p2, q2] (vectorized), by the clamped closest-point parameters of the
    two lines (parallel segments: the first parameter 0, then clamped)."""
    p1, q1, p2, q2 = (np.asarray(x, float) for x in (p1, q1, p2, q2))
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e = np.sum(d1 * d1, axis=-1), np.sum(d2 * d2, axis=-1)
    b, c, f = np.sum(d1 * d2, axis=-1), np.sum(d1 * r, axis=-1), np.sum(d2 * r, axis=-1)
    sa, se = np.where(a > 0, a, 1.0), np.where(e > 0, e, 1.0)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-14 * a * e, np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0, 1), 0.0)
    s = np.where(a > 0, s, 0.0)
    t = np.where(e > 0, (b * s + f) / se, 0.0)
    low, high = t < 0, t > 1
    t = np.clip(t, 0, 1)
    s = np.where(low, np.clip(-c / sa, 0, 1), np.where(high, np.clip((b - c) / sa, 0, 1), s))
    s = np.where(e > 0, s, np.clip(-c / sa, 0, 1))  # the second segment a point: its nearest point on the first
    s = np.where(a > 0, s, 0.0)
    return s, t
