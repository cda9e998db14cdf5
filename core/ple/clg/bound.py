"""The conical-shell bound of a CLG solid (thesis §5.5, Fig. 5.5; §8.2): the volume between two
cones that share their apex F, the fixed point of the pattern's similarities, and their axis T,
the axis of rotation of the similarities, cut by the two spheres about F that the log-polar bounds
of §8.1 use.

Every copy of a chunk is a spiral similarity about F and T of the chunk at group 0 (a rotation
about T times a dilation about F), so the angle φ between T and the vector from F to a point is
the same in every copy, and the distance from F is multiplied by the copy's factor. The shell
``{X : φ(X) ∈ [φ0, φ1], |FX| ∈ [d0, d1]}`` of the group-0 primitives, with d0 and d1 stretched by
the smallest and largest factor of the count range, therefore holds every copy.

Unlike the thesis' figure (which bounds the smallest ball around each cone-beam), the angular range
of a ball is exact (its cap as seen from F) and a cone-beam, the union of the balls interpolated
between its end balls, is cut into short pieces, each bounded by the smallest ball around it; the
excess over the exact range is at most half a piece length over the distance from F. A pattern
whose similarities have no common fixed point and axis (translations, screws, or one count only)
has no conical shell: ``conical_shell`` returns None and only the box bound applies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..algebra.elements import beam_distance, enclosing_ball
from ..algebra.similarity import Similarity
from ..algebra.vectors import unit

PIECE = 0.05  # a cone-beam piece is at most this fraction of its smaller end radius long
MAX_PIECES = 512
TOL = 1e-9  # relative slack for round-off (the bound must never cut a primitive)


@dataclass(frozen=True)
class ConicalShell:
    """Apex F (3,), unit axis T (3,), angle range [φ0, φ1] ⊂ [0, π] from T, distance range [d0, d1]."""

    apex: np.ndarray
    axis: np.ndarray
    phi: tuple[float, float]
    dist: tuple[float, float]

    def touches(self, points, radii) -> np.ndarray:
        """bool (q,): may ball (P, r) meet the shell? Never False when it does (the test compares the
        ball's own angle and distance ranges as seen from F with the shell's)."""
        p = np.asarray(points, float).reshape(-1, 3)
        r = np.broadcast_to(np.asarray(radii, float), (len(p),))
        v = p - self.apex
        d = np.linalg.norm(v, axis=1)
        phi = np.arctan2(np.linalg.norm(np.cross(v, self.axis), axis=1), v @ self.axis)
        half = np.arcsin(np.clip(r / np.where(d > 0, d, 1.0), 0.0, 1.0))
        radial = (d + r >= self.dist[0]) & (d - r <= self.dist[1])
        angular = (phi + half >= self.phi[0]) & (phi - half <= self.phi[1])
        return (d <= r) | (radial & angular)

    def contains(self, points) -> np.ndarray:
        return self.touches(points, 0.0)


def _generators(lat, region) -> list[np.ndarray]:
    """World-frame similarities between neighbouring copies (``M_e ∘ G⁻¹``) of the directions
    that repeat within the index range."""
    ginv = np.linalg.inv(lat.placement.matrix)
    shape = region.shape if region is not None else lat.counts
    out = []
    for axis, n in enumerate(shape):
        if n > 1:
            e = np.zeros(3, np.int64)
            e[axis] = 1
            out.append(lat.group_matrices(e[:1], e[1:2], e[2:])[0] @ ginv)
    return out


def _apex_axis(gens: list[np.ndarray], near: np.ndarray, scale: float):
    """(F, T) shared by every generator, or None: each must fix F and rotate about T (or not rotate)."""
    sims = [Similarity.from_matrix(m) for m in gens]
    sims = [s for s in sims if s.kind != "identity"]
    if not sims or any(s.kind in ("translation", "screw") for s in sims):
        return None
    dil = [s for s in sims if s.kind in ("scaling", "swirl")]
    if dil:
        apex = dil[0].p
    else:  # rotations only: any point of the common axis; the one nearest the template
        r, p = sims[0].r, sims[0].p
        apex = p + ((near - p) @ r) * r
    turning = [s.r for s in sims if s.angle != 0.0]
    axis = turning[0] if turning else unit(near - apex) if np.linalg.norm(near - apex) > TOL * scale else None
    if axis is None:
        return None
    for m, s in zip(gens, sims):
        if np.linalg.norm(m[:3, :3] @ apex + m[:3, 3] - apex) > 1e-7 * scale:
            return None
        if s.angle != 0.0 and np.linalg.norm(np.cross(s.r, axis)) > 1e-7:
            return None
    return apex, axis


def _angles(apex, axis, c, r):
    """(φ − half, φ + half) of balls (c (m, 3), r (m,)) as seen from the apex: their exact caps."""
    v = c - apex
    d = np.linalg.norm(v, axis=1)
    phi = np.arctan2(np.linalg.norm(np.cross(v, axis), axis=1), v @ axis)
    half = np.where(r < d, np.arcsin(np.clip(r / np.where(d > 0, d, 1.0), 0.0, 1.0)), np.pi)
    return phi - half, phi + half


def conical_shell(lat, prims: list, region=None) -> ConicalShell | None:
    """The conical shell holding every copy (over ``region`` or the whole count range) of the
    group-0 primitives ``prims``, a list of (ca (3,), ra, cb (3,) or None, rb) in world coordinates."""
    if not prims:
        return None
    centres = np.array([p[0] for p in prims] + [p[2] for p in prims if p[2] is not None])
    near = centres.mean(axis=0)
    scale = max(1.0, float(np.abs(centres).max()))
    found = _apex_axis(_generators(lat, region), near, scale)
    if found is None:
        return None
    apex, axis = found
    lo, hi, d0, d1 = [], [], [], []
    for ca, ra, cb, rb in prims:
        ca = np.asarray(ca, float)
        if cb is None:
            c, r = ca[None], np.array([ra])
            d0.append(np.linalg.norm(ca - apex) - ra)
            d1.append(np.linalg.norm(ca - apex) + ra)
        else:
            cb = np.asarray(cb, float)
            # the beam is the union of balls B(c(t), r(t)), t ∈ [0, 1]: pieces [t, t'] lie in the
            # hull of their end balls, bounded by its smallest ball
            n = int(min(MAX_PIECES, max(1, math.ceil(np.linalg.norm(cb - ca) / (PIECE * min(ra, rb))))))
            t = np.linspace(0.0, 1.0, n + 1)
            cc, rr = ca + t[:, None] * (cb - ca), ra + t * (rb - ra)
            c, r = enclosing_ball(cc[:-1], rr[:-1], cc[1:], rr[1:])
            d0.append(float(beam_distance(apex[None], ca, ra, cb, rb)[0]))
            d1.append(max(np.linalg.norm(ca - apex) + ra, np.linalg.norm(cb - apex) + rb))  # |FX| is convex
        a, b = _angles(apex, axis, c, r)
        lo.append(a.min())
        hi.append(b.max())
    phi0, phi1 = max(0.0, min(lo) - TOL), min(math.pi, max(hi) + TOL)
    fmin, fmax = _factor_range(lat, region)
    dist0 = max(0.0, min(d0)) * fmin * (1 - TOL) - TOL * scale
    dist1 = max(d1) * fmax * (1 + TOL) + TOL * scale
    return ConicalShell(apex, axis, (phi0, phi1), (max(0.0, dist0), dist1))


def _factor_range(lat, region) -> tuple[float, float]:
    """Smallest and largest factor of the copies M_g ∘ G⁻¹: a product of powers, extreme at the
    corners of the index box."""
    if region is None:
        ranges = [(0, n - 1) for n in lat.counts]
    else:
        ranges = [(region.i0, region.i1 - 1), (region.j0, region.j1 - 1), (region.k0, region.k1 - 1)]
    g = np.array(np.meshgrid(*ranges, indexing="ij")).reshape(3, -1)
    f = lat.group_factors(g[0], g[1], g[2]) / lat.placement.factor
    return float(f.min()), float(f.max())
