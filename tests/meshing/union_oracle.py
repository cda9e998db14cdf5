"""An independent oracle of the exact solid a lattice stands for: the union of its balls and
cone-beams (a cone-beam is the convex hull of its two balls), with a Monte Carlo volume. Written
from the geometry only (no ple meshing or measure code), for tests of the meshes.

A point p is in the hull of balls (c1, r1), (c2, r2) (|r1 − r2| < L = |c2 − c1|) iff it is in
one of the balls, or in the truncated cone between their tangent circles: with u the axis, x the
axial and ρ the radial coordinate of p from c1 and sin φ = (r1 − r2) / L, the cone's profile is
the line x sin φ + ρ cos φ = r1 in the (x, ρ) half-plane, between the tangent points at
x = r1 sin φ and x = L + r2 sin φ.
"""

from __future__ import annotations

import numpy as np


def in_ball(p: np.ndarray, c: np.ndarray, r: float) -> np.ndarray:
    """Which points p (N, 3) lie in the ball (c, r): (N,)."""
    d = p - c
    return np.einsum("ni,ni->n", d, d) <= r * r


def in_cone_beam(p: np.ndarray, c1: np.ndarray, r1: float, c2: np.ndarray, r2: float) -> np.ndarray:
    """Which points p (N, 3) lie in the convex hull of the balls (c1, r1) and (c2, r2): (N,)."""
    axis = c2 - c1
    length = float(np.linalg.norm(axis))
    inside = in_ball(p, c1, r1) | in_ball(p, c2, r2)
    if length <= abs(r1 - r2):  # one ball holds the other: their hull is the larger
        return inside
    u = axis / length
    q = p - c1
    x = q @ u
    rho = np.linalg.norm(q - x[:, None] * u, axis=1)
    s = (r1 - r2) / length
    c = np.sqrt(1 - s * s)
    cone = (x >= r1 * s) & (x <= length + r2 * s) & (x * s + rho * c <= r1)
    return inside | cone


def _sampling_box(c1: np.ndarray, r1: float, c2: np.ndarray, r2: float):
    """A box holding the cone-beam of (c1, r1), (c2, r2), aligned with its axis: (origin (3,),
    edge vectors (3, 3)); the box from the ball centre c1 - r1 u to c2 + r2 u, of half-width
    max(r1, r2) across (an axis-aligned box of a diagonal beam is mostly empty)."""
    axis = c2 - c1
    length = float(np.linalg.norm(axis))
    u = axis / length if length > 0 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(u, np.eye(3)[np.argmin(np.abs(u))])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    w = max(r1, r2)
    origin = c1 - r1 * u - w * (e1 + e2)
    return origin, np.stack([(length + r1 + r2) * u, 2 * w * e1, 2 * w * e2])


def union_volume(center: np.ndarray, radius: np.ndarray, beams: np.ndarray, samples: int = 4000,
                 seed: int = 0) -> tuple[float, float]:
    """Monte Carlo volume of the union of balls (center (B, 3), radius (B,)) and cone-beams
    (beams (E, 2) ball indices), stratified by element: each element k (balls, then beams) gets
    ``samples`` points uniform in a box holding it (a ball's cube, a beam's box along its axis),
    and counts those inside it and inside no element before it, so the union's volume is the sum
    over elements of box volume × that fraction, every point of the union counted once. Returns
    (estimate, standard error sqrt(Σ V_k² f_k (1 − f_k) / samples))."""
    rng = np.random.default_rng(seed)
    beams = np.asarray(beams, np.int64).reshape(-1, 2)
    a, b = beams[:, 0], beams[:, 1]
    # axis-aligned bounds of every element: which earlier elements a sample may lie in
    ra, rb = radius[a, None], radius[b, None]
    lo = np.concatenate([center - radius[:, None], np.minimum(center[a] - ra, center[b] - rb)])
    hi = np.concatenate([center + radius[:, None], np.maximum(center[a] + ra, center[b] + rb)])
    nb = len(center)

    def inside(k, p):
        if k < nb:
            return in_ball(p, center[k], radius[k])
        x, y = beams[k - nb]
        return in_cone_beam(p, center[x], radius[x], center[y], radius[y])

    total, var = 0.0, 0.0
    for k in range(len(lo)):
        if k < nb:
            origin, edges = center[k] - radius[k], 2 * radius[k] * np.eye(3)
        else:
            x, y = beams[k - nb]
            origin, edges = _sampling_box(center[x], radius[x], center[y], radius[y])
        p = origin + rng.random((samples, 3)) @ edges
        keep = inside(k, p)
        for e in np.flatnonzero(np.all((lo[:k] <= hi[k]) & (hi[:k] >= lo[k]), axis=1)):
            sel = np.flatnonzero(keep)
            if not len(sel):
                break
            keep[sel[inside(e, p[sel])]] = False
        f = keep.mean()
        box = abs(float(np.linalg.det(edges)))
        total += f * box
        var += box * box * f * (1 - f) / samples
    return total, float(np.sqrt(var))
