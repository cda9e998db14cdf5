"""Graded thickness: radius fields multiplying node radii by a factor of the ball's world centre.

A lattice with a radius field (``Lattice.set_radius_field``) has node radii
``r = r_template · s_group · f(centre)``: every evaluation (``node_balls``, ``region_balls``,
``evaluate``) applies it, so filters, queries, measures and meshes see the graded radii. Each
field states ``bound``, an upper bound of its factor: queries search candidates on the steady
lattice with radii × bound (a superset) and test the candidates with the true radii.

Fields: ``LinearGradient`` (between two points), ``GridField`` (a 3-D array over a box, trilinear),
``FunctionField`` (a Python function of the positions, in programs); the distance to a body's
surface is ``ple.filters.body.SurfaceDistanceField``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from ..algebra.vectors import Pt
from ..errors import PleError


class RadiusField(ABC):
    """A positive factor per world point, at most ``bound``."""

    bound: float

    @abstractmethod
    def values(self, points: np.ndarray) -> np.ndarray:
        """Factors (N,) at points (N, 3)."""

    def factors(self, points) -> np.ndarray:
        """Checked factors (N,): finite, positive, at most ``bound`` (else a PleError naming the field)."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        f = np.asarray(self.values(p), dtype=float).reshape(-1)
        if f.shape != (len(p),):
            raise PleError(f"{self!r}: returned {f.size} factors for {len(p)} points")
        bad = ~np.isfinite(f) | (f <= 0) | (f > self.bound * (1 + 1e-12))
        if bad.any():
            raise PleError(f"{self!r}: factor {f[bad][0]!r} at {p[bad][0].tolist()} is not in (0, {self.bound:g}]")
        return f


MAX_FACTOR = 1e6  # a radius factor beyond this is a typo, and f0 + (f1 - f0) t would lose f1 to rounding


def _positive(x, what: str) -> float:
    x = float(x)
    if not np.isfinite(x) or x <= 0 or x > MAX_FACTOR:
        raise PleError(f"{what} must be a positive number up to {MAX_FACTOR:g}, got {x!r}")
    return x


class LinearGradient(RadiusField):
    """Factor ``f0`` at point ``a``, ``f1`` at point ``b``, linear along a→b between them and
    constant beyond (the projection onto the segment is clamped)."""

    def __init__(self, a, b, f0: float = 1.0, f1: float = 2.0) -> None:
        self.a, self.b = Pt(a), Pt(b)
        self.d = self.b - self.a
        self.dd = float(self.d @ self.d)
        if not 0 < self.dd < np.inf or not (np.all(np.isfinite(self.a)) and np.all(np.isfinite(self.b))):
            raise PleError("a gradient needs two distinct finite points (their distance squared finite)")
        self.f0, self.f1 = _positive(f0, "gradient factor f0"), _positive(f1, "gradient factor f1")
        self.bound = max(self.f0, self.f1)

    def values(self, points):
        t = np.clip((points - self.a) @ self.d / self.dd, 0.0, 1.0)
        return self.f0 + (self.f1 - self.f0) * t

    def __repr__(self) -> str:
        return f"LinearGradient({self.a.tolist()}, {self.b.tolist()}, {self.f0:g}, {self.f1:g})"


class GridField(RadiusField):
    """Factors sampled on a regular grid ``values`` (nx, ny, nz) spanning the box lo..hi (corner
    samples on its corners), interpolated trilinearly; points outside take the nearest face's."""

    def __init__(self, values, lo, hi) -> None:
        v = np.asarray(values, dtype=float)
        if v.ndim != 3 or min(v.shape) < 2:
            raise PleError(f"a grid field needs an (nx, ny, nz) array with at least 2 samples a side, got {v.shape}")
        if not np.all(np.isfinite(v)) or v.min() <= 0:
            raise PleError("grid field values must be finite and positive")
        self.v, self.lo, self.hi = v, Pt(lo), Pt(hi)
        if np.any(self.hi <= self.lo):
            raise PleError("grid field box: hi must exceed lo on every axis")
        self.bound = float(v.max())

    def values(self, points):
        n = np.array(self.v.shape) - 1
        x = np.clip((points - self.lo) / (self.hi - self.lo), 0.0, 1.0) * n
        i = np.minimum(np.floor(x).astype(np.int64), n - 1)
        u = x - i
        out = np.zeros(len(points))
        for corner in np.ndindex(2, 2, 2):
            w = np.prod(np.where(np.array(corner), u, 1 - u), axis=1)
            out += w * self.v[i[:, 0] + corner[0], i[:, 1] + corner[1], i[:, 2] + corner[2]]
        return out

    def __repr__(self) -> str:
        return f"GridField({self.v.shape})"


class FunctionField(RadiusField):
    """``fn(points (N, 3)) -> (N,)`` factors, with a stated ``bound`` (checked on every call)."""

    def __init__(self, fn, bound: float) -> None:
        if not callable(fn):
            raise PleError("a function field needs a callable of the points")
        self.fn, self.bound = fn, _positive(bound, "function field bound")

    def values(self, points):
        return self.fn(points)

    def __repr__(self) -> str:
        return f"FunctionField({getattr(self.fn, '__name__', 'fn')}, bound={self.bound:g})"
