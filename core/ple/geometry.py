"""Points and vectors of the program API (``Pt``, ``Vec``) and small array helpers."""

from __future__ import annotations

import numpy as np

from .errors import PleError


def _as3(values, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (3,):
        raise PleError(f"{what}: expected 3 coordinates, got {np.asarray(values).tolist()!r}")
    if not np.all(np.isfinite(arr)):
        raise PleError(f"{what}: coordinates must be finite, got {arr.tolist()!r}")
    return arr


def Pt(x, y=None, z=None) -> np.ndarray:  # noqa: N802 - thesis API name
    """A 3D point, ``Pt(x, y, z)`` or ``Pt([x, y, z])``; returns a float array of shape (3,)."""
    return _as3([x, y, z] if y is not None else x, "Pt")


def Vec(x, y=None, z=None) -> np.ndarray:  # noqa: N802 - thesis API name
    """A 3D vector, ``Vec(x, y, z)`` or ``Vec([x, y, z])``; returns a float array of shape (3,)."""
    return _as3([x, y, z] if y is not None else x, "Vec")


def unit(v, what: str = "axis") -> np.ndarray:
    """``v`` normalized; a zero (or non-finite) vector is a user error naming ``what``."""
    v = _as3(v, what)
    scale = float(np.abs(v).max())
    if not np.isfinite(scale):
        raise PleError(f"{what}: must be finite, got {v.tolist()}")
    if scale * float(np.linalg.norm(v / scale if scale > 0 else v)) < 1e-12:
        raise PleError(f"{what}: zero vector has no direction")
    v = v / scale  # first: the norm of [1e308, 1e308, 0] would overflow
    return v / np.linalg.norm(v)


def rotation_matrices(axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rodrigues rotation matrices about unit ``axis`` for each angle: shape (len(angles), 3, 3)."""
    angles = np.asarray(angles, dtype=float).reshape(-1)
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    kk = k @ k
    s = np.sin(angles)[:, None, None]
    c = (1.0 - np.cos(angles))[:, None, None]
    return np.eye(3)[None] + s * k[None] + c * kk[None]
