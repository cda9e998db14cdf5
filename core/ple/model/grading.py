"""Graded thickness: radius fields multiplying node radii by a factor of the ball's world centre.

A lattice with a radius field (``Lattice.set_radius_field``) has node radii
``r = r_template · s_group · f(centre)``: every evaluation (``node_balls``, ``region_balls``,
``evaluate``) applies it, so filters, queries, measures and meshes see the graded radii. Each
field states ``bound``, an upper bound of its factor: queries search candidates on the steady
lattice with radii × bound (a superset) and test the candidates with the true radii.

Fields: ``LinearGradient`` (between two points), ``GridField`` (a 3-D array over a box, trilinear),
``FunctionField`` (a Python function of the positions, in programs); the distance to a body's
surface is ``ple.filters.body.SurfaceDistanceField``.

In ``ple-lattice/1`` a field is the data ``"grade"`` (docs/formats.md): ``grade_to_dict`` and
``grade_from_dict`` (strict: every malformed entry is named by its path, e.g.
``grade.values[2][0][1]``). A function field is code, not data: it is refused.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from ..algebra.vectors import Pt
from ..errors import PleError, cut, echo

GRADE_KINDS = ("linear", "grid", "surface")
MAX_GRID_VALUES = 1 << 21  # samples of a grid field written as data


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
            raise PleError(f"{echo(self)}: returned {f.size} factors for {len(p)} points")
        bad = ~np.isfinite(f) | (f <= 0) | (f > self.bound * (1 + 1e-12))
        if bad.any():
            raise PleError(f"{echo(self)}: factor {echo(f[bad][0])} at {p[bad][0].tolist()} "
                           f"is not in (0, {self.bound:g}]")
        return f


MAX_FACTOR = 1e6  # a radius factor beyond this is a typo, and f0 + (f1 - f0) t would lose f1 to rounding


def _positive(x, what: str) -> float:
    x = float(x)
    if not np.isfinite(x) or x <= 0 or x > MAX_FACTOR:
        raise PleError(f"{what} must be a positive number up to {MAX_FACTOR:g}, got {echo(x)}")
    return x


class LinearGradient(RadiusField):
    """Factor ``f0`` at point ``a``, ``f1`` at point ``b``, linear along a→b between them and
    constant beyond (the projection onto the segment is clamped)."""

    def __init__(self, a, b, f0: float = 1.0, f1: float = 2.0) -> None:
        self.a, self.b = Pt(a), Pt(b)
        with np.errstate(over="ignore", invalid="ignore"):  # points far apart overflow: refused just below
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


# ----- ple-lattice/1 data ------------------------------------------------------------------------------
def grade_to_dict(field: RadiusField) -> dict:
    """The ``"grade"`` data of a linear or grid field (others are refused naming their type)."""
    if isinstance(field, LinearGradient):
        return {"kind": "linear", "a": field.a.tolist(), "b": field.b.tolist(), "f0": field.f0, "f1": field.f1}
    if isinstance(field, GridField):
        return {"kind": "grid", "lo": field.lo.tolist(), "hi": field.hi.tolist(), "values": field.v.tolist()}
    raise PleError(f"grade: a {type(field).__name__} cannot be written as data (linear, grid and surface "
                   "fields can; a function field is code: keep the program)")


def _keys(d, where: str, required: tuple, optional: tuple = ()) -> None:
    if not isinstance(d, dict):
        raise PleError(f"{where}: expected an object with {', '.join(required)}")
    for key in required:
        if key not in d:
            raise PleError(f"{where}.{key}: missing")
    for key in d:
        if key not in required and key not in optional:
            raise PleError(f"{where}.{cut(key)}: unknown field (expected some of {', '.join(required + optional)})")


def _number(x, where: str, positive: bool = False) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise PleError(f"{where}: expected a finite number, got {echo(x)}")
    if positive and x <= 0:
        raise PleError(f"{where}: must be positive, got {echo(x)}")
    return float(x)


def _point(x, where: str) -> list[float]:
    if not isinstance(x, list) or len(x) != 3:
        raise PleError(f"{where}: expected a list of 3 numbers, got {echo(x)}")
    return [_number(c, f"{where}[{n}]") for n, c in enumerate(x)]


def _grid_values(v, where: str) -> np.ndarray:
    """A nested (nx, ny, nz) list of positive numbers, every row of one length, checked entry by entry."""
    shape = []
    probe = v
    for _ in range(3):
        if not isinstance(probe, list) or not probe:
            raise PleError(f"{where}: expected a non-empty 3-D list (x, then y, then z), got {echo(probe)}"[:200])
        shape.append(len(probe))
        probe = probe[0]
    if math.prod(shape) > MAX_GRID_VALUES:
        raise PleError(f"{where}: {math.prod(shape):,} samples (limit {MAX_GRID_VALUES:,})")
    out = np.empty(shape)
    for i, plane in enumerate(v):
        if not isinstance(plane, list) or len(plane) != shape[1]:
            raise PleError(f"{where}[{i}]: expected {shape[1]} rows like {where}[0]")
        for j, row in enumerate(plane):
            if not isinstance(row, list) or len(row) != shape[2]:
                raise PleError(f"{where}[{i}][{j}]: expected {shape[2]} numbers like {where}[0][0]")
            for k, x in enumerate(row):
                out[i, j, k] = _number(x, f"{where}[{i}][{j}][{k}]", positive=True)
    return out


def grade_from_dict(d, where: str = "grade", surface=None) -> RadiusField:
    """The radius field of ``"grade"`` data. ``surface(depth, f_surface, f_deep, where)`` makes a
    surface-distance field (it needs the lattice's body: ``ple.filters.ir`` gives one); without
    it a surface grade is refused."""
    kind = d.get("kind") if isinstance(d, dict) else None
    if kind not in GRADE_KINDS:
        if not isinstance(d, dict):
            raise PleError(f"{where}: expected an object with kind ({', '.join(GRADE_KINDS)})")
        raise PleError(f"{where}.kind: expected one of {', '.join(GRADE_KINDS)}, got {echo(kind)}")
    try:
        if kind == "linear":
            _keys(d, where, ("kind", "a", "b"), ("f0", "f1"))
            return LinearGradient(_point(d["a"], f"{where}.a"), _point(d["b"], f"{where}.b"),
                                  _number(d.get("f0", 1.0), f"{where}.f0", True),
                                  _number(d.get("f1", 2.0), f"{where}.f1", True))
        if kind == "grid":
            _keys(d, where, ("kind", "lo", "hi", "values"))
            return GridField(_grid_values(d["values"], f"{where}.values"), _point(d["lo"], f"{where}.lo"),
                             _point(d["hi"], f"{where}.hi"))
        _keys(d, where, ("kind", "depth"), ("f_surface", "f_deep"))
        depth = _number(d["depth"], f"{where}.depth", True)
        fs = _number(d.get("f_surface", 2.0), f"{where}.f_surface", True)
        fd = _number(d.get("f_deep", 1.0), f"{where}.f_deep", True)
    except PleError as exc:
        msg = str(exc)
        raise PleError(msg if msg.startswith(where) else f"{where}: {msg}") from None
    if surface is None:
        raise PleError(f"{where}: a surface grade needs the lattice's body (load the file with ple.io.irfile.load_ir)")
    return surface(depth, fs, fd, where)
