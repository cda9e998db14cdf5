"""Guards for interactive front ends: a work estimate before long work, a time limit on
programs, numbers at the precision a float32 frame carries.

``estimate`` counts balls, beams, triangles and memory of a region from the lattice's counts,
template and beam-patterns alone (no evaluation), so a front end can refuse a 400³ region
before allocating anything. The counts of balls and beams are exact before filters (filters
only remove); triangles and bytes are calibrated approximations (see docs/addon.md).
``time_limit`` stops a program that runs too long (``while True: pass``) with a PleError.
``frame_number`` / ``frame_similarity`` drop float32 noise from numbers read off frames.
"""

from __future__ import annotations

import math
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from .errors import PleError
from .lattice import Lattice
from .similarity import Similarity, similarity_from_dict

# triangles per beam end of a tessellation style (measured on cubic, octet and fig6_3 3³
# regions: chocc 41-53, cnt 12-17, refined at 4 levels 1825-2521 = about 8-10 x 4**levels)
TRIANGLES_PER_BEAM_END = {"chocc": 55.0, "cnt": 18.0, "balls-beams": 8.0}
REFINED_PER_BEAM_END_LEVEL0 = 10.0
TRIANGLES_PER_BALL = {"chocc": 24.0, "cnt": 24.0, "refined": 24.0, "balls-beams": 80.0}  # bare caps, icospheres
# bytes per drawn element: the core's evaluation (measured peak about 200 B a ball and 100 B a beam)
# plus Blender's mesh and balls-and-beams drawing (issue 15 measured 9.9 GB for 8 M balls and 24 M
# beams: about 310 B an element in all)
BYTES_PER_BALL = 400
BYTES_PER_BEAM = 300
BYTES_PER_TRIANGLE = 150  # core arrays (faces, vertices) and the Blender mesh built from them


@dataclass(frozen=True)
class Estimate:
    """Work of drawing or tessellating a region, before evaluating anything."""

    groups: int
    balls: int
    beams: int
    triangles: int
    bytes: int

    def describe(self) -> str:
        tri = f", {_big(self.triangles)} triangles" if self.triangles else ""
        return (f"{_big(self.groups)} node-groups: {_big(self.balls)} balls, {_big(self.beams)} beams{tri}, "
                f"about {_bytes(self.bytes)}")


def _big(n: int) -> str:
    for size, unit in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if n >= size:
            return f"{n / size:.3g}{unit}"
    return str(int(n))


def _bytes(n: float) -> str:
    for size, unit in ((2**30, "GB"), (2**20, "MB"), (2**10, "kB")):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} B"


def estimate(lat: Lattice, region=None, style: str | None = None, levels: int = 4) -> Estimate:
    """Balls, beams (exact, before filters), triangles of ``style`` (0 if None) and memory of a
    region. A beam-pattern with offset (di, dj, dk) joins a group to one inside the region in
    prod(max(0, shape - |d|)) groups of a shape-(a, b, c) region."""
    r = lat.region(region)
    shape = r.shape
    groups = math.prod(shape)
    balls = groups * len(lat.nodes)
    beams = sum(math.prod(max(0, s - abs(d)) for s, d in zip(shape, (b.di, b.dj, b.dk))) for b in lat.beams)
    triangles = 0
    if style is not None:
        per_end = (REFINED_PER_BEAM_END_LEVEL0 * 4.0 ** levels if style == "refined"
                   else TRIANGLES_PER_BEAM_END.get(style))
        if per_end is None:
            raise PleError(f"style {style!r}: expected one of chocc, cnt, refined, balls-beams")
        triangles = int(2 * beams * per_end + balls * TRIANGLES_PER_BALL[style])
    size = BYTES_PER_BALL * balls + BYTES_PER_BEAM * beams + BYTES_PER_TRIANGLE * triangles
    return Estimate(groups, balls, beams, triangles, int(size))


def check(est: Estimate, max_bytes: float | None = None, max_triangles: float | None = None,
          what: str = "this") -> Estimate:
    """``est`` if it is within the limits, else a PleError giving the estimate and the limit."""
    if max_bytes is not None and est.bytes > max_bytes:
        raise PleError(f"{what} refused: {est.describe()} — beyond the memory limit of {_bytes(max_bytes)} "
                       "(raise it in the add-on preferences, or choose a smaller region)")
    if max_triangles is not None and est.triangles > max_triangles:
        raise PleError(f"{what} refused: {est.describe()} — beyond the limit of {_big(int(max_triangles))} "
                       "triangles (raise it in the add-on preferences, or choose a smaller region)")
    return est


# ----- a time limit on programs ------------------------------------------------------------------
class ProgramTimeoutError(PleError):
    """A program ran beyond its time limit."""


@contextmanager
def time_limit(seconds: float | None, filename: str):
    """Raise ProgramTimeoutError inside code compiled as ``filename`` once ``seconds`` have passed.

    Only the program's own frames are traced (line events), so core calls run at full speed;
    a single long core call (one huge numpy operation) is not interrupted, the next program
    line is. ``seconds`` None or <= 0: no limit."""
    if not seconds or seconds <= 0:
        yield
        return
    deadline = time.monotonic() + float(seconds)

    def local(frame, event, arg):
        if time.monotonic() > deadline:
            raise ProgramTimeoutError(f"stopped after the time limit of {seconds:g} s (a loop that never ends? "
                                      "a program that needs longer: raise the limit)")
        return local

    def outer(frame, event, arg):
        if frame.f_code.co_filename != filename:
            return None
        return local(frame, event, arg)

    old = sys.gettrace()
    sys.settrace(outer)
    try:
        yield
    finally:
        sys.settrace(old)


# ----- numbers read off float32 frames -------------------------------------------------------------
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
