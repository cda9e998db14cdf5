"""The work of a region, before evaluating anything: node-groups, balls, beams and memory from the
lattice's counts, template and beam-patterns alone, so a front end can refuse a 400³ region before
allocating anything. The counts of balls and beams are exact before filters (filters only remove);
bytes (and the triangles a tessellation style adds, ``meshing.styles.mesh_estimate``) are
calibrated approximations (see docs/addon.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import PleError
from .lattice import Lattice

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

    def with_triangles(self, triangles: int) -> Estimate:
        """This estimate with ``triangles`` (of a tessellation) counted, memory included."""
        triangles = int(triangles)
        extra = BYTES_PER_TRIANGLE * (triangles - self.triangles)
        return replace(self, triangles=triangles, bytes=int(self.bytes + extra))


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


def estimate(lat: Lattice, region=None) -> Estimate:
    """Node-groups, balls and beams (exact, before filters) and memory of drawing a region
    (no triangles). A beam-pattern with offset (di, dj, dk) joins a group to one inside the
    region in prod(max(0, shape - |d|)) groups of a shape-(a, b, c) region."""
    shape = lat.region(region).shape
    groups = math.prod(shape)
    balls = groups * len(lat.nodes)
    beams = sum(math.prod(max(0, s - abs(d)) for s, d in zip(shape, (b.di, b.dj, b.dk))) for b in lat.beams)
    return Estimate(groups, balls, beams, 0, int(BYTES_PER_BALL * balls + BYTES_PER_BEAM * beams))


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
