"""Fitted symmetric fields as CLG solids (004_ §3.2 fields used for hierarchical structures, thesis §10.1).

A ``FieldSolid`` is the region {Φ ≤ level} of a Fourier field Φ (``ple fit``'s output, or any
``FourierField``). It replaces a primitive's material like a CLG L does (§10.1): a primitive X
with such a material is X ∩ {Φ ≤ level}, the field placed in the world frame or in the
primitive's own frame (a ball: its centre, unit = its radius; a beam: origin at the first
centre, +x to the second, unit = the beam's length). So a shape fitted to a mesh can sit, scaled
and moved, in every ball of a lattice, or a periodic fitted field can fill its beams.

Values follow the CLG query contract (``ple.clg.query``): the sign is exact (PMC), and the
magnitude is a *lower bound* of the distance to {Φ = level}: ``(Φ − level) / L`` with L a
Lipschitz bound of Φ, 2π Σ |c_f| |f| per cell unit (a real Fourier series' gradient is at most
that), so sphere tracing never steps over the surface. Values are clipped to [−R, R] like every
other leaf. In ``ple-clg/1`` the coefficients are inline data (``field_to_dict``).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PleError, cut, echo
from ..filters.implicit import FourierField

MAX_TERMS = 200_000  # coefficients of an inline field in a ple-clg/1 file
FIELD_KEYS = {"n", "freqs", "coeffs", "symmetric", "cell", "level"}


class FieldSolid:
    """{Φ ≤ level} of a Fourier field, usable as a material's ``replace`` in a CLG."""

    depth = 1  # a leaf: nothing nested below it

    def __init__(self, field: FourierField, level: float = 0.0):
        if not isinstance(field, FourierField):
            raise PleError(f"a field solid needs a FourierField (e.g. FourierField.load of `ple fit`'s file), "
                           f"got {type(field).__name__}")
        level = float(level)
        if not math.isfinite(level):
            raise PleError(f"field level must be finite, got {level}")
        self.field, self.level = field, level
        self.lipschitz = lipschitz_bound(field)

    def value(self, points, radii=None) -> np.ndarray:
        """(Φ − level) / L per point (N,): exact sign, a lower bound of the distance to the
        surface; clipped to [−R, R] where ``radii`` R > 0 (the CLG query contract)."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        v = (self.field(p) - self.level) / self.lipschitz if self.lipschitz > 0 else self.field(p) - self.level
        if radii is None:
            return v
        r = np.broadcast_to(np.asarray(radii, float), v.shape)
        return np.where(r > 0, np.clip(v, -r, r), v)

    def pmc(self, points) -> np.ndarray:
        return self.value(points) <= 0


def lipschitz_bound(field: FourierField) -> float:
    """A bound of |∇Φ| in world units: 2π Σ |c_f| |f| over the real series' terms, divided by
    the smallest cell side and the placement's factor."""
    f, c, w = field._half  # each ±f pair once, weight 2: Re Σ c_f e^{2πi f·x} = Σ w (a cos − b sin)
    per_cell = 2 * math.pi * float(np.sum(w * np.abs(c) * np.linalg.norm(f, axis=1)))
    return per_cell / (float(np.min(field.cell)) * field.placement.factor)


def field_to_dict(solid: FieldSolid) -> dict:
    """The inline ``ple-clg/1`` data of a field solid: ``{"fourier": {n, freqs, coeffs, ...}}``."""
    fld = solid.field
    if not np.allclose(fld.placement.matrix, np.eye(4)):
        raise PleError("a field with a placement cannot be written to ple-clg/1 (place it by the material's frame)")
    cell = fld.cell.tolist() if np.ndim(fld.cell) else float(fld.cell)
    return {"fourier": {"n": fld.n, "freqs": fld.freqs.tolist(),
                        "coeffs": np.column_stack([fld.coeffs.real, fld.coeffs.imag]).tolist(),
                        "symmetric": fld.symmetric, "cell": cell, "level": solid.level}}


def field_from_dict(data, where: str) -> FieldSolid:
    """A field solid from its inline data (see ``field_to_dict``); errors name the JSON path."""
    if not isinstance(data, dict):
        raise PleError(f"{where}: expected an object with n, freqs, coeffs")
    bad = sorted(set(data) - FIELD_KEYS)
    if bad:
        raise PleError(f"{where}.{cut(bad[0])}: unknown field (expected some of {', '.join(sorted(FIELD_KEYS))})")
    for key in ("n", "freqs", "coeffs"):
        if key not in data:
            raise PleError(f"{where}.{key}: missing")
    n = data["n"]
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 1024:
        raise PleError(f"{where}.n: expected an integer order 1..1024, got {echo(n)}")
    freqs, coeffs = _array(data["freqs"], f"{where}.freqs"), _array(data["coeffs"], f"{where}.coeffs")
    if freqs.shape[0] != coeffs.shape[0]:
        raise PleError(f"{where}.coeffs: {coeffs.shape[0]} coefficients for {freqs.shape[0]} frequencies")
    if freqs.shape[0] > MAX_TERMS:
        raise PleError(f"{where}.freqs: {freqs.shape[0]} terms exceed the limit {MAX_TERMS}")
    if freqs.shape[1:] != (3,) or np.any(freqs != np.round(freqs)) or np.any(np.abs(freqs) > n):
        raise PleError(f"{where}.freqs: expected integer triples [fx, fy, fz] with |f| <= n")
    if coeffs.shape[1:] != (2,):
        raise PleError(f"{where}.coeffs: expected [real, imaginary] pairs")
    sym = data.get("symmetric", False)
    if not isinstance(sym, bool):
        raise PleError(f"{where}.symmetric: expected true or false, got {echo(sym)}")
    cell = data.get("cell", 1.0)
    if not (isinstance(cell, (int, float)) and not isinstance(cell, bool)) and not (
            isinstance(cell, list) and len(cell) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in cell)):
        raise PleError(f"{where}.cell: expected a positive number or three, got {echo(cell)}")
    level = data.get("level", 0.0)
    if isinstance(level, bool) or not isinstance(level, (int, float)):
        raise PleError(f"{where}.level: expected a number, got {echo(level)}")
    try:
        fld = FourierField(freqs.astype(np.int64), coeffs[:, 0] + 1j * coeffs[:, 1], n, cell=cell, symmetric=sym)
        return FieldSolid(fld, level)
    except PleError as exc:
        raise PleError(f"{where}: {exc}") from None


def _array(x, where: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise PleError(f"{where}: expected a list of number lists") from None
    if a.ndim != 2 or not np.all(np.isfinite(a)):
        raise PleError(f"{where}: expected a list of finite number lists")
    return a
