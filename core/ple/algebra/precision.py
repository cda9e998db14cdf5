"""Numbers read off float32 frames (Blender's matrices): the shortest decimal within the precision
a float32 frame carries, for points and for similarities, so a dragged handle gives 0.3, not
0.300000014338."""

from __future__ import annotations

import numpy as np

from ..errors import PleError
from .similarity import Similarity, similarity_from_dict

FLOAT32_TOL = 2.0 ** -22  # two units in the last place of a float32 (24-bit significand)


def frame_number(x: float, scale: float = 1.0, rel: float = FLOAT32_TOL) -> float:
    """The shortest decimal within the precision a float32 frame carries: |result - x| <=
    max(|x|, scale) * rel (rel = 2**-22 by default); values below scale * rel are 0
    (e.g. 0.300000014338 -> 0.3)."""
    x = float(x)
    tol = max(abs(x), float(scale)) * rel
    if abs(x) <= tol:
        return 0.0
    for digits in range(1, 18):
        v = float(f"{x:.{digits}g}")
        if abs(v - x) <= tol:
            return v
    return x


def frame_point(p, scale: float = 1.0) -> tuple:
    """``frame_number`` of each coordinate of ``p``."""
    return tuple(frame_number(c, scale) for c in p)


def frame_similarity(sim: Similarity, scale: float = 1.0) -> Similarity:
    """``sim`` with its parameters as short as the precision of a float32 frame of size
    ``scale`` allows: positions and distances relative to ``scale``; angles, axes and factors
    relative to 1. The result's matrix stays within float32 precision of ``sim``'s (a swirl
    whose fixed point lies far away is sensitive to its factor): where plain rounding would move
    it more, fewer digits are dropped, down to none."""
    d = sim.to_dict()
    m0 = sim.matrix
    limit = FLOAT32_TOL * np.array([[1.0] * 3 + [max(1.0, float(scale))]] * 3)
    for rel in (FLOAT32_TOL, FLOAT32_TOL / 16, FLOAT32_TOL / 256, FLOAT32_TOL / 4096):
        out = {"kind": d["kind"]}
        for key, val in d.items():
            if key == "kind":
                continue
            unit = scale if key in ("point", "vector", "distance") else 1.0
            out[key] = ([frame_number(c, unit, rel) for c in val] if isinstance(val, list)
                        else frame_number(val, unit, rel))
        try:
            got = similarity_from_dict(out)
        except PleError:
            continue
        if np.all(np.abs(got.matrix[:3] - m0[:3]) <= limit):
            return got
    return sim
