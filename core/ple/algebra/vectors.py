"""Points and vectors of the program API (``Pt``, ``Vec``) and the vector helpers every layer uses:
unit vectors, fast cross products, perpendicular frames, rotations about an axis, index runs."""

from __future__ import annotations

import numpy as np

from ..errors import PleError, echo


def as3(values, what: str) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (3,):
        raise PleError(f"{what}: expected 3 coordinates, got {echo(np.asarray(values).tolist())}")
    if not np.all(np.isfinite(arr)):
        raise PleError(f"{what}: coordinates must be finite, got {echo(arr.tolist())}")
    return arr


def Pt(x, y=None, z=None) -> np.ndarray:  # noqa: N802 - thesis API name
    """A 3D point, ``Pt(x, y, z)`` or ``Pt([x, y, z])``; returns a float array of shape (3,)."""
    return as3([x, y, z] if y is not None else x, "Pt")


def Vec(x, y=None, z=None) -> np.ndarray:  # noqa: N802 - thesis API name
    """A 3D vector, ``Vec(x, y, z)`` or ``Vec([x, y, z])``; returns a float array of shape (3,)."""
    return as3([x, y, z] if y is not None else x, "Vec")


def unit(v, what: str = "axis") -> np.ndarray:
    """``v`` normalized; a zero (or non-finite) vector is a user error naming ``what``."""
    v = as3(v, what)
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


def unit_rows(v) -> np.ndarray:
    """Rows of ``v`` (..., 3) normalized along the last axis; zero rows stay zero."""
    v = np.asarray(v, float)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def cross(a, b) -> np.ndarray:
    """Cross product over the last axis (broadcasting); np.cross is slow on small arrays."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def perpendicular_frames(normals) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (e1, e2) orthogonal to each row of unit ``normals`` (..., 3), with
    (e1, e2, n) right-handed; e1 is built from the x axis, or the y axis when n is near x."""
    normals = np.asarray(normals, float)
    helper = np.where(np.abs(normals[..., :1]) < 0.9, [1.0, 0, 0], [0, 1.0, 0])
    e1 = unit_rows(cross(normals, helper))
    return e1, cross(normals, e1)


def rotate(v, axis: np.ndarray, angles) -> np.ndarray:
    """Rodrigues: rotate vectors ``v`` (n, 3) about unit ``axis`` by ``angles`` (n,)."""
    v = np.asarray(v, float)
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    return v * c + cross(axis, v) * s + axis * (v @ axis)[:, None] * (1.0 - c)


def runs(start, count) -> np.ndarray:
    """The indices start[k], …, start[k] + count[k] − 1 of every k (K,), one run after the other
    (sum(count),): the gather of K variable-length slices of a flat array at once."""
    start, count = np.asarray(start, np.int64), np.asarray(count, np.int64)
    return np.repeat(start - (np.cumsum(count) - count), count) + np.arange(int(count.sum()))
