"""Work budget: what a command or the add-on will produce, estimated from the program before
allocating (docs/reliability.md, docs/addon.md), and the finiteness of a lattice's extremes.

The one place both doors estimate work: node-groups, balls and beams of a region (exact before
filters: filters only remove), triangles of a tessellation style (``mesh_triangles``, calibrated
from above) and memory. Every command that allocates in proportion to its output calls
``require`` with an estimate of its peak memory; beyond ``--max-memory`` (default: a quarter of
the machine's RAM, or the ``PLE_MAX_MEMORY`` environment variable) it is refused with the
estimate and the flag. The add-on takes an ``Estimate`` of drawing or tessellating a region and
``check``s it against the limits of its preferences. The flags themselves (``--max-memory``,
``--timeout``) belong to the CLI's shared arguments.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, replace
from itertools import product

import numpy as np

from ..errors import PleError, echo
from .lattice import Lattice, Region

ENV = "PLE_MAX_MEMORY"
HUGE = 1e100  # coordinates and radii beyond this are refused: volumes (cubes) must stay finite
DEFAULT_FRACTION = 0.25
_UNITS = {"": 1, "B": 1, "K": 1 << 10, "KB": 1 << 10, "M": 1 << 20, "MB": 1 << 20, "G": 1 << 30,
          "GB": 1 << 30, "T": 1 << 40, "TB": 1 << 40}


def physical_memory() -> int:
    """Bytes of RAM (sysconf; 8 GiB if unknown)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def parse_size(text: str, flag: str = "--max-memory") -> int:
    """``2G``, ``512M``, ``1.5GB``, ``1000000`` to bytes."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([KMGT]?B?)\s*", str(text), re.IGNORECASE)
    if not m:
        raise PleError(f"{flag} {echo(text)}: expected a size such as 2G, 512M or 1.5GB")
    value = float(m.group(1)) * _UNITS[m.group(2).upper()]
    if not math.isfinite(value) or value < 1 << 20:
        raise PleError(f"{flag} {echo(text)}: expected at least 1M")
    return int(value)


def default_max_memory() -> int:
    env = os.environ.get(ENV)
    if env:
        return parse_size(env, ENV)
    return int(physical_memory() * DEFAULT_FRACTION)


def human(n: float) -> str:
    """Bytes for people: ``1.5 GiB``."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def big(n: float) -> str:
    """Counts for people: ``64 M``."""
    for size, unit in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if n >= size:
            return f"{n / size:.3g}{unit}"
    return str(int(n))


def require(estimate: float, what: str, limit: int, hint: str = "") -> None:
    """Refuse work whose estimated peak memory exceeds ``limit``."""
    if estimate > limit:
        raise PleError(f"{what} needs about {human(estimate)} (estimated before starting), more than the "
                       f"limit {human(limit)}; {hint + ', or ' if hint else ''}raise it with --max-memory")


# ----- counts from the program alone -------------------------------------------------------------
def region_nodes(lat: Lattice, r: Region) -> int:
    return r.groups * len(lat.nodes)


def region_beams(lat: Lattice, r: Region) -> int:
    """Beams with both ends in the region (exact: a product per beam-pattern)."""
    return sum(math.prod(max(0, n - abs(d)) for n, d in zip(r.shape, b.offset)) for b in lat.beams)


EVAL_NODE_BYTES = 4 * 8 + 3 * 8 + 8  # node_index, center, radius
EVAL_BEAM_BYTES = 4 * 8 + 2 * 8
PEAK_FACTOR = 3  # temporaries while building the arrays (meshgrids, sort permutations)


def evaluation_bytes(lat: Lattice, r: Region) -> float:
    """Peak bytes of ``Lattice.evaluate(r)`` (and of its ``.npz``)."""
    return PEAK_FACTOR * (region_nodes(lat, r) * EVAL_NODE_BYTES + region_beams(lat, r) * EVAL_BEAM_BYTES)


def hub_triangles(degree: float, style: str, levels: int, segments: int) -> float:
    """Estimate (from above, measured within 2x on the presets) of the triangles of one hub of
    ``degree`` beams with half of each of its beam strips. CNT: 2d - 4 hub triangles and d
    corridor quads (CHoCC paper 001_ §5); each refinement level splits every hub triangle in
    4 and doubles every ring of a beam strip (§6)."""
    d = max(degree, 1.0)
    if style == "balls-beams":
        return 80 + 10 * d
    if style == "chocc":
        return 2 * d + 4 + 1.5 * d * segments
    lv = levels if style == "refined" else 0
    return (4 * d + 4) * 4.0 ** lv + 6 * d * 2.0 ** lv


MESH_TRIANGLE_BYTES = 300  # peak per triangle while building (measured 120-240: vertices, faces, copies)
CLG_TRIANGLE_BYTES = 650  # manifold3d's copies, their union and the trimesh (measured 540-600 with the interpreter)


def sphere_triangles(segments: int) -> int:
    """Triangles of manifold3d's sphere of ``segments`` circle segments (``Manifold.sphere``: s²/2);
    a CLG beam, the hull of two spheres, has at most twice as many."""
    return int(segments) ** 2 // 2
CHECK_TRIANGLE_BYTES = 600  # with --check (trimesh's watertightness and volume; measured 545)


STL_BOUND = 2.0  # real triangles / ``mesh_triangles`` measured at most 1.31 on the presets' styles


def streamed_stl_bytes(triangles: float) -> float:
    """An upper bound of the binary STL of a mesh estimated at ``triangles`` (``mesh_triangles``
    times ``STL_BOUND``, 50 bytes a triangle): what the disk must hold before a stream starts."""
    return 84 + 50 * STL_BOUND * triangles


def mean_degree(lat: Lattice) -> float:
    return 2 * len(lat.beams) / max(len(lat.nodes), 1)


def mesh_triangles(lat: Lattice, r: Region, style: str, levels: int, segments: int) -> float:
    """Triangles of tessellating region ``r`` in ``style`` (``levels`` of refinement, ``segments``
    per corridor circle): ``hub_triangles`` per ball, read by the CLI, batch jobs and the add-on."""
    return region_nodes(lat, r) * hub_triangles(mean_degree(lat), style, levels, segments)


# ----- the work of a region, as the add-on checks it ---------------------------------------------
# bytes per drawn element: the core's evaluation (measured peak about 200 B a ball and 100 B a beam)
# plus Blender's mesh and balls-and-beams drawing (issue 15 measured 9.9 GB for 8 M balls and 24 M
# beams: about 310 B an element in all)
DRAW_BALL_BYTES = 400
DRAW_BEAM_BYTES = 300


@dataclass(frozen=True)
class Estimate:
    """Work of drawing (or tessellating) a region, before evaluating anything."""

    groups: int
    balls: int
    beams: int
    triangles: int
    bytes: int

    def describe(self) -> str:
        tri = f", {big(self.triangles)} triangles" if self.triangles else ""
        return (f"{big(self.groups)} node-groups: {big(self.balls)} balls, {big(self.beams)} beams{tri}, "
                f"about {human(self.bytes)}")

    def with_triangles(self, triangles: float) -> Estimate:
        """This estimate with ``triangles`` (of a tessellation) counted, their memory included
        (``MESH_TRIANGLE_BYTES`` each)."""
        triangles = int(triangles)
        extra = MESH_TRIANGLE_BYTES * (triangles - self.triangles)
        return replace(self, triangles=triangles, bytes=int(self.bytes + extra))


def estimate(lat: Lattice, region=None) -> Estimate:
    """Node-groups, balls and beams (exact, before filters: ``region_nodes``, ``region_beams``)
    and the memory of drawing a region in Blender (no triangles)."""
    r = lat.region(region)
    balls, beams = region_nodes(lat, r), region_beams(lat, r)
    return Estimate(r.groups, balls, beams, 0, int(DRAW_BALL_BYTES * balls + DRAW_BEAM_BYTES * beams))


def check(est: Estimate, max_bytes: float | None = None, max_triangles: float | None = None,
          what: str = "this", hint: str = "raise it in the add-on preferences, or choose a smaller region") -> Estimate:
    """``est`` if it is within the limits, else a PleError giving the estimate, the limit and
    ``hint`` (how to raise it)."""
    if max_bytes is not None and est.bytes > max_bytes:
        raise PleError(f"{what} refused: {est.describe()} — beyond the memory limit of {human(max_bytes)} ({hint})")
    if max_triangles is not None and est.triangles > max_triangles:
        raise PleError(f"{what} refused: {est.describe()} — beyond the limit of {big(int(max_triangles))} "
                       f"triangles ({hint})")
    return est


# ----- finiteness --------------------------------------------------------------------------------
TINY = 1e-100  # radii below this are refused: volumes (cubes) must stay normal, non-zero floats
PRECISION = 2.0 ** -50  # a ball smaller than this share of the lattice's largest coordinate is placed
# to less than about a quarter of its radius (float64 keeps 52 bits): its digits are lost (a Möbius
# slab's far balls, 23 units in the last place of their coordinates, are kept)


def _ball_problem(centers: np.ndarray, radii: np.ndarray) -> tuple[str, str] | None:
    """What is wrong with these balls (centres (N, 3), radii (N,)) of one lattice, as (what
    happens, the numbers), or None: overflow (non-finite, or beyond ``HUGE``), underflow (radii
    zero or below ``TINY``) or total loss of precision (a radius below ``PRECISION`` of the largest
    coordinate)."""
    with np.errstate(all="ignore"):
        if not (np.isfinite(centers).all() and np.isfinite(radii).all()):
            return "overflows", "infinite or undefined coordinates or radii"
        far, top = float(np.abs(centers).max(initial=0.0)), float(radii.max(initial=0.0))
        if far >= HUGE or top >= HUGE:
            return "overflows", f"coordinates or radii up to {max(far, top):.3g}, beyond {HUGE:.0e}"
        low = float(radii.min(initial=np.inf))
        if low < TINY:
            return "underflows to zero scale", (f"radii down to {low:.3g}, below the smallest meaningful "
                                                f"size {TINY:.0e}")
        if low < PRECISION * far:
            return ("loses all precision", f"balls of radius {low:.3g} at coordinates up to {far:.3g}, which "
                    "float64 cannot place")
    return None


def _corner_balls(lat: Lattice, corners) -> tuple[np.ndarray, np.ndarray]:
    """Centres and radii of every node of the groups ``corners`` (G, 3)."""
    idx = np.asarray(corners, dtype=np.int64).reshape(-1, 3)
    nn = len(lat.nodes)
    full = np.column_stack([np.repeat(idx, nn, axis=0), np.tile(np.arange(nn), len(idx))])
    with np.errstate(all="ignore"):
        return lat.node_balls(full)


def check_lattice(lat: Lattice, what: str = "the lattice") -> None:
    """The one check of a built lattice that every door calls (IR files, programs run for the
    CLI, batch and the add-on): no beam-pattern given twice (``check_beam_patterns``) and every
    number representable (``check_finite``)."""
    check_beam_patterns(lat, what)
    check_finite(lat, what)


def check_beam_patterns(lat: Lattice, what: str = "the lattice") -> None:
    """Refuse a beam-pattern that repeats an earlier one, as given or reversed ((n1, n2, d) and
    (n2, n1, -d) join the same balls): the same beams twice would be measured twice (areas and
    volumes) and meshed as overlapping copies."""
    seen: dict[tuple, int] = {}
    for pos, b in enumerate(lat.beams):
        key = (b.n1, b.n2, b.offset)
        rev = (b.n2, b.n1, tuple(-x for x in b.offset))
        first = seen.get(min(key, rev))
        if first is not None:
            raise PleError(f"{what}: beam-pattern beams[{pos}] (node {b.n1} to node {b.n2}, offset {b.offset}) repeats "
                           f"beams[{first}]: each beam would be there twice; remove the copy")
        seen[min(key, rev)] = pos


def check_finite(lat: Lattice, what: str = "the lattice") -> None:
    """The one check of a lattice's numbers that every door calls (IR files, programs, the
    add-on's rigs through the runner): at every corner group the balls are finite and under
    ``HUGE``, the radii at least ``TINY``, and no radius below ``PRECISION`` of the largest
    coordinate. The powers of the similarities are monotone in scale, so an overflow,
    an underflow to zero scale or a loss of precision shows at a corner. Raises PleError naming
    the direction (U, V, W), its similarity and its repetition count, or the template."""
    if not lat.nodes:
        return
    corners = np.array(list(product(*[(0, n - 1) if n > 1 else (0,) for n in lat.counts])), dtype=np.int64)
    problem = _ball_problem(*_corner_balls(lat, corners))
    if problem is None:
        return
    verb, numbers = problem
    if lat.group_map is not None:  # groups placed by a map: no direction to blame
        raise PleError(f"{what} {verb}: its {lat.group_map.kind} map gives {numbers}")
    if _ball_problem(*_corner_balls(lat, [(0, 0, 0)])) is not None:
        raise PleError(f"{what} {verb}: node-group (0, 0, 0) already has {numbers}; check the template's "
                       "radii and the placement")
    blame = []
    for axis, (name, d) in enumerate((("U", lat.u), ("V", lat.v), ("W", lat.w))):
        if d.count > 1:
            end = [0, 0, 0]
            end[axis] = d.count - 1
            if _ball_problem(*_corner_balls(lat, [(0, 0, 0), end])) is not None:
                s = d.incremental
                factor = f", factor {s.factor:.6g}" if s.factor != 1 else ""
                blame.append(f"{name} (a {s.kind}{factor}, count {d.count})")
    if not blame:
        blame = ["U, V and W together"]
    cause = ", ".join(blame[:-1]) + " and " + blame[-1] if len(blame) > 1 else blame[0]
    raise PleError(f"{what} {verb}: the powers of {cause} give {numbers}; use a smaller count or a "
                   "milder similarity")


# ----- cheap answers for huge lattices -----------------------------------------------------------
MONOTONE_KINDS = ("identity", "translation", "scaling")
MAX_SCAN_GROUPS = 1 << 20


def axis_samples(lat: Lattice, max_groups: int = MAX_SCAN_GROUPS, region=None) -> tuple[list[np.ndarray], bool]:
    """Indices per axis whose groups bound the whole lattice (or ``region``), and whether that is
    exact.

    Node-group (i, j, k) is G W^k V^j U^i N (SPEC §3): every index enters through its own power
    only, so where that similarity is a translation or a scaling each coordinate (and the
    radius) is affine in i, resp. in s^i, monotone in i: the two end indices bound the axis
    exactly. Other axes are scanned whole when the product stays within ``max_groups``,
    else sampled evenly (approximate)."""
    r = lat.region(region)
    dirs = (lat.U, lat.V, lat.W)
    ranges = ((r.i0, r.i1), (r.j0, r.j1), (r.k0, r.k1))
    samples: list[np.ndarray | None] = [None, None, None]
    for a, (s, (lo, hi)) in enumerate(zip(dirs, ranges)):
        if s.kind in MONOTONE_KINDS or hi - lo <= 2:
            samples[a] = np.unique([lo, hi - 1])
    budget = max_groups // max(1, math.prod(len(x) for x in samples if x is not None))
    free = [a for a in range(3) if samples[a] is None]
    exact = True
    for a in free:
        share = max(2, int(budget ** (1 / len(free))))
        lo, hi = ranges[a]
        if hi - lo <= share:
            samples[a] = np.arange(lo, hi)
        else:
            samples[a] = np.unique(np.linspace(lo, hi - 1, share).round().astype(np.int64))
            exact = False
    return samples, exact


def fast_bounds(lat: Lattice, region=None) -> tuple[np.ndarray, np.ndarray, bool]:
    """Axis-aligned bounds of all balls of the program (before any filter) in ``region``
    (default: all) from the groups of ``axis_samples``: (min, max, exact)."""
    lat.validate()
    (si, sj, sk), exact = axis_samples(lat, region=region)
    gi, gj, gk = (g.reshape(-1) for g in np.meshgrid(si, sj, sk, indexing="ij"))
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    nn = len(lat.nodes)
    step = max(1, (1 << 18) // nn)
    for s in range(0, len(gi), step):
        sel = slice(s, s + step)
        g = len(gi[sel])
        idx = np.column_stack([np.repeat(np.column_stack([gi[sel], gj[sel], gk[sel]]), nn, axis=0),
                               np.tile(np.arange(nn), g)])
        c, r = lat.node_balls(idx)
        lo = np.minimum(lo, (c - r[:, None]).min(axis=0))
        hi = np.maximum(hi, (c + r[:, None]).max(axis=0))
    return lo, hi, exact


def estimate_hits(lat: Lattice, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Approximate hits (nodes + beams) per query ball: the lattice's elements times the share
    of its bounding box that the ball's box (grown by a cell and the largest ball) covers."""
    lo, hi, _ = fast_bounds(lat)
    extent = hi - lo
    total = lat.node_count() + lat.beam_count()
    cell = extent / max(1.0, lat.groups ** (1 / 3))
    grow = radii[:, None] + cell[None] + float(lat.template_radii.max())
    q_lo, q_hi = centers - grow, centers + grow
    overlap = np.clip(np.minimum(q_hi, hi) - np.maximum(q_lo, lo), 0, None)
    share = np.where(extent > 0, overlap / np.where(extent > 0, extent, 1), (overlap > 0) | (q_lo <= lo))
    return total * np.prod(np.clip(share, 0, 1), axis=1)


HIT_ARRAY_BYTES = 4 * 8 * 2  # one (i, j, k, n) row, and its sort copy
HIT_LISTED_BYTES = 4 * 8 * 2 + 4 * 36 + 40  # plus the Python list of 4 ints and its JSON text


def slab_groups_within(lat: Lattice, slab_groups: int, limit: int) -> int:
    """The streamed slab size (node-groups) shrunk so that a slab and the few i-layers of row
    maps kept for beams (``ple.io.chunks``) fit in ``limit``; PleError if one group does not."""
    per_group = 2 * PEAK_FACTOR * (len(lat.nodes) * EVAL_NODE_BYTES + len(lat.beams) * EVAL_BEAM_BYTES)
    fit = limit // max(per_group, 1)
    if fit < 1:
        require(per_group, "one node-group", limit)
    return int(max(1, min(int(slab_groups), fit)))


RANGEFINDER_ROW_BYTES = 600  # per row × element of the "u"/"uv" paths (measured 550 on thesis_warped)


def rangefinder_bytes(lat: Lattice, path: str, queries: int) -> float:
    """Peak bytes of a RangeFinder BIQ (§7.3.1): the "1" path works per query and element, the
    "u" path per U index, the "uv" path per W-row (i, j) of the whole lattice."""
    ne = len(lat.nodes) + len(lat.beams)
    nu, nv, _ = lat.counts
    rows = {"1": queries, "u": (queries + 1) * nu, "uv": nu * nv + queries * nu}.get(path, queries)
    return float(rows) * ne * RANGEFINDER_ROW_BYTES
