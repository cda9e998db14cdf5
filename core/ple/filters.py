"""Filters for hierarchical lattices (thesis §9): index stencils, Lattice-in-Lattice, compounds.

A filter decides per node (thesis §9: F(N) -> true/false) from the node's index (i, j, k, n)
and its ball; a beam survives when both of its nodes survive. Filters compose with ``&``,
``|`` and ``~`` and are applied lazily: ``FilteredLattice(lat, f).evaluate(region)`` evaluates
only that region of the lattice. A Lattice-in-Lattice (LiL) filter keeps a fine node when
its ball interferes with a coarse lattice (a ball or a cone-beam of it); the coarse lattice
may itself be a ``FilteredLattice``, which gives the cascades of thesis Fig. 9.3.
"""

from __future__ import annotations

import math
import os
from abc import ABC, abstractmethod
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .elements import ball_ball_interfere, ball_beam_interfere
from .errors import PleError
from .lattice import Evaluation, Lattice, Region

MAX_COARSE_NODES = 20_000_000  # a coarse lattice is evaluated in full; beyond this it is not "coarse"
QUERY_CHUNK = 1 << 17  # query balls per vectorized batch (bounds the candidate-pair memory)
THREADS = min(4, os.cpu_count() or 1)
MAX_CELL_ENTRIES = 4_000_000  # (grid cell, element) candidates before the exact reach test

MAX_STENCIL_CELLS = 10**8  # a named stencil's period box (a Boolean array of this size)


# ----- the filter model ------------------------------------------------------------------------
class Filter(ABC):
    """Decides per node. Subclasses implement ``node_mask``."""

    @abstractmethod
    def node_mask(self, lat: Lattice, node_index: np.ndarray, center: np.ndarray, radius: np.ndarray) -> np.ndarray:
        """bool (N,): which nodes survive, given node_index (N, 4), centres (N, 3) and radii (N,)."""

    def __and__(self, other: Filter) -> Filter:
        return And(self, _as_filter(other))

    def __or__(self, other: Filter) -> Filter:
        return Or(self, _as_filter(other))

    def __invert__(self) -> Filter:
        return Not(self)

    def apply(self, lat: Lattice, region=None) -> Evaluation:
        """The surviving nodes and beams of a region of ``lat`` (default: the whole lattice)."""
        return FilteredLattice(lat, self).evaluate(region)


def _as_filter(f) -> Filter:
    if not isinstance(f, Filter):
        raise PleError(f"cannot combine a filter with {type(f).__name__}")
    return f


class And(Filter):
    """A node survives when every part keeps it (evaluated left to right on the survivors)."""

    def __init__(self, *parts: Filter) -> None:
        self.parts = parts

    def node_mask(self, lat, node_index, center, radius):
        keep = np.ones(len(node_index), dtype=bool)
        for part in self.parts:
            rows = np.flatnonzero(keep)  # later parts only see nodes still alive (LiL is the costly one)
            if rows.size == 0:
                break
            keep[rows] = part.node_mask(lat, node_index[rows], center[rows], radius[rows])
        return keep


class Or(Filter):
    """A node survives when any part keeps it."""

    def __init__(self, *parts: Filter) -> None:
        self.parts = parts

    def node_mask(self, lat, node_index, center, radius):
        keep = np.zeros(len(node_index), dtype=bool)
        for part in self.parts:
            rows = np.flatnonzero(~keep)
            if rows.size == 0:
                break
            keep[rows] = part.node_mask(lat, node_index[rows], center[rows], radius[rows])
        return keep


class Not(Filter):
    def __init__(self, part: Filter) -> None:
        self.part = part

    def node_mask(self, lat, node_index, center, radius):
        return ~self.part.node_mask(lat, node_index, center, radius)


def select(ev: Evaluation, keep: np.ndarray) -> Evaluation:
    """Keep the nodes flagged in ``keep`` (N,) and the beams whose two nodes are both kept;
    beam_nodes are renumbered to rows of the kept nodes."""
    keep = np.asarray(keep, dtype=bool)
    new_row = np.cumsum(keep) - 1
    beam_alive = keep[ev.beam_nodes[:, 0]] & keep[ev.beam_nodes[:, 1]] if len(ev.beam_nodes) else \
        np.zeros(0, dtype=bool)
    return Evaluation(ev.node_index[keep], ev.center[keep], ev.radius[keep], ev.beam_index[beam_alive],
                      new_row[ev.beam_nodes[beam_alive]].reshape(-1, 2).astype(np.int64))


class FilteredLattice:
    """A lattice seen through a filter; evaluated lazily, region by region."""

    def __init__(self, lattice: Lattice, filter: Filter) -> None:
        if not isinstance(lattice, Lattice):
            raise PleError(f"a filtered lattice needs a Lattice, got {type(lattice).__name__}")
        self.lattice = lattice
        self.filter = _as_filter(filter)

    def node_mask(self, node_index, center, radius) -> np.ndarray:
        return self.filter.node_mask(self.lattice, node_index, center, radius)

    def region_rows(self, region) -> tuple[Evaluation, np.ndarray]:
        """Surviving nodes of a region (an Evaluation without beams) and the region's row map:
        int64 (ni, nj, nk, nn), the survivor's row or -1 for a removed node."""
        lat = self.lattice
        r = lat.region(region)
        centers, radii = lat.region_balls(r)
        index = r.node_index(len(lat.nodes))
        keep = self.node_mask(index, centers.reshape(-1, 3), radii.reshape(-1))
        rows = np.where(keep, np.cumsum(keep) - 1, -1).reshape(radii.shape)
        nodes = Evaluation(index[keep], centers.reshape(-1, 3)[keep], radii.reshape(-1)[keep],
                           np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64))
        return nodes, rows

    def evaluate(self, region=None) -> Evaluation:
        """Surviving nodes and beams with both ends in ``region`` (arrays as ``ple eval``)."""
        r = self.lattice.region(region)
        ev, rows = self.region_rows(r)
        ev.beam_index, ev.beam_nodes = beams_between(self.lattice, r, rows, r, rows)
        return ev


def beams_between(lat: Lattice, a: Region, rows_a: np.ndarray, b: Region, rows_b: np.ndarray):
    """Beams whose from-group lies in box ``a`` and to-group in box ``b``, both nodes alive.

    ``rows_a``/``rows_b`` (ni, nj, nk, nn) give each node's output row, -1 where removed.
    Returns beam_index (M, 4) and beam_nodes (M, 2), sorted by (i, j, k, pattern)."""
    lo_all, hi_all, boxes = np.full(3, np.iinfo(np.int64).max), np.full(3, np.iinfo(np.int64).min), []
    for p, bp in enumerate(lat.beams):
        lo = np.maximum((a.i0, a.j0, a.k0), np.subtract((b.i0, b.j0, b.k0), bp.offset))
        hi = np.minimum((a.i1, a.j1, a.k1), np.subtract((b.i1, b.j1, b.k1), bp.offset))
        if np.all(hi > lo):
            boxes.append((p, bp, lo, hi))
            lo_all, hi_all = np.minimum(lo_all, lo), np.maximum(hi_all, hi)
    if not boxes:
        return np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64)
    # one Boolean array over (i, j, k, pattern): np.nonzero then lists beams already sorted
    alive = np.zeros((*(hi_all - lo_all), len(lat.beams)), dtype=bool)
    a0, b0 = np.array((a.i0, a.j0, a.k0)), np.array((b.i0, b.j0, b.k0))
    keep_a = rows_a >= 0
    keep_b = keep_a if rows_b is rows_a else rows_b >= 0
    for p, bp, lo, hi in boxes:
        fa = keep_a[tuple(slice(x, y) for x, y in zip(lo - a0, hi - a0)) + (bp.n1,)]
        tb = keep_b[tuple(slice(x, y) for x, y in zip(lo + bp.offset - b0, hi + bp.offset - b0)) + (bp.n2,)]
        np.logical_and(fa, tb, out=alive[tuple(slice(x, y) for x, y in zip(lo - lo_all, hi - lo_all)) + (p,)])
    flat = np.flatnonzero(alive)  # linear (i, j, k, pattern) positions, in sorted order
    nb = len(lat.beams)
    ext = hi_all - lo_all
    pp = flat % nb
    g = flat // nb
    kk = g % ext[2] + lo_all[2]
    g //= ext[2]
    jj = g % ext[1] + lo_all[1]
    ii = g // ext[1] + lo_all[0]
    n1 = np.array([bp.n1 for bp in lat.beams])[pp]
    n2 = np.array([bp.n2 for bp in lat.beams])[pp]
    off = np.array([bp.offset for bp in lat.beams], dtype=np.int64)[pp]
    index = np.empty((len(flat), 4), dtype=np.int64)
    index[:, 0], index[:, 1], index[:, 2], index[:, 3] = ii, jj, kk, pp
    ends = np.empty((len(flat), 2), dtype=np.int64)
    ends[:, 0] = _lookup(rows_a, a, ii, jj, kk, n1)
    ends[:, 1] = _lookup(rows_b, b, ii + off[:, 0], jj + off[:, 1], kk + off[:, 2], n2)
    return index, ends


def _lookup(rows: np.ndarray, box: Region, i, j, k, n) -> np.ndarray:
    """rows[i - i0, j - j0, k - k0, n] through one linear index (faster than 4-D fancy indexing)."""
    _, nj, nk, nn = rows.shape
    return rows.reshape(-1)[(((i - box.i0) * nj + (j - box.j0)) * nk + (k - box.k0)) * nn + n]


# ----- index stencils (thesis §9: F(N) = S[i mod x, j mod y, k mod z]) ---------------------------
STENCIL_NAMES = ("corners", "edges", "faces", "checker", "layers")


class Stencil(Filter):
    """Boolean stencil S of shape (x, y, z), or (x, y, z, nn) to decide per node id as well."""

    def __init__(self, array) -> None:
        s = np.asarray(array)
        if s.dtype != bool:
            if not np.issubdtype(s.dtype, np.number) or not np.isin(s, (0, 1)).all():
                raise PleError("stencil must be a Boolean (or 0/1) array")
            s = s.astype(bool)
        if s.ndim not in (3, 4) or min(s.shape) < 1:
            raise PleError(f"stencil must have shape (x, y, z) or (x, y, z, nodes), got {s.shape}")
        self.array = s

    def node_mask(self, lat, node_index, center, radius):
        s = self.array
        idx = np.asarray(node_index, dtype=np.int64)
        key = (idx[:, 0] % s.shape[0], idx[:, 1] % s.shape[1], idx[:, 2] % s.shape[2])
        if s.ndim == 4:
            if s.shape[3] != len(lat.nodes):
                raise PleError(f"stencil has {s.shape[3]} node columns but the lattice has {len(lat.nodes)} nodes")
            key = key + (idx[:, 3],)
        return s[key]

    @staticmethod
    def named(name: str, period=4, width: int = 1) -> Stencil:
        """Common hierarchical patterns over a period box (x, y, z):
        ``corners`` keeps groups with all three indices ≡ 0 (isolated clusters), ``edges`` those
        with at least two ≡ 0 (a coarse cubic frame whose beams are made of fine beams),
        ``faces`` those with at least one ≡ 0 (coarse cell walls), ``checker`` alternate blocks
        of a 2x2x2 checkerboard, ``layers`` the first ``width`` k-layers of every period."""
        per = (period,) * 3 if np.isscalar(period) else tuple(period)
        if len(per) != 3 or any(int(p) != p or p < 1 for p in per):
            raise PleError(f"stencil period must be a positive integer or three of them, got {period!r}")
        if int(width) != width or width < 1:
            raise PleError(f"stencil width must be a positive integer, got {width!r}")
        x, y, z = (int(p) for p in per)
        if x * y * z > MAX_STENCIL_CELLS:
            raise PleError(f"stencil period {x}x{y}x{z} has more than {MAX_STENCIL_CELLS:,} cells")
        i, j, k = np.meshgrid(np.arange(x), np.arange(y), np.arange(z), indexing="ij")
        on = [(i % x) < width, (j % y) < width, (k % z) < width]
        hits = on[0].astype(int) + on[1] + on[2]
        if name == "corners":
            s = hits == 3
        elif name == "edges":
            s = hits >= 2
        elif name == "faces":
            s = hits >= 1
        elif name == "checker":
            s = ((2 * i // x) + (2 * j // y) + (2 * k // z)) % 2 == 0
        elif name == "layers":
            s = on[2]
        else:
            raise PleError(f"unknown stencil {name!r}; named stencils: {', '.join(STENCIL_NAMES)}")
        return Stencil(s)

    @staticmethod
    def parse(text: str) -> Stencil:
        """``NAME[:P|PxQxR][:W]`` (a named stencil) or a ``.npy`` file holding a Boolean array."""
        if text.endswith(".npy"):
            from .schema import load_npy

            return Stencil(load_npy(text, "--stencil"))
        parts = text.split(":")
        try:
            period = [int(p) for p in parts[1].split("x")] if len(parts) > 1 else [4]
            width = int(parts[2]) if len(parts) > 2 else 1
        except ValueError:
            raise PleError(f"--stencil {text!r}: expected NAME[:PERIOD or PxQxR][:WIDTH]") from None
        if len(period) not in (1, 3) or len(parts) > 3:
            raise PleError(f"--stencil {text!r}: expected NAME[:PERIOD or PxQxR][:WIDTH]")
        return Stencil.named(parts[0], period[0] if len(period) == 1 else period, width)


# ----- spatial index over the elements of a (filtered) coarse lattice ---------------------------
class ElementSet:
    """Balls and cone-beams, indexed in a uniform grid for ``any_hit`` batch queries; the exact
    ball–ball and ball–cone-beam tests are those of ``ple.elements`` (touching counts).

    Each element is entered in the grid cells it may reach within ``reach`` (the largest query
    radius to come); a query ball is tested exactly against the elements of its centre's cell."""

    def __init__(self, center: np.ndarray, radius: np.ndarray, beam_nodes: np.ndarray, reach: float) -> None:
        self.center = np.asarray(center, dtype=float).reshape(-1, 3)
        self.radius = np.asarray(radius, dtype=float).reshape(-1)
        self.beam_nodes = np.asarray(beam_nodes, dtype=np.int64).reshape(-1, 2)
        self.reach = float(reach)
        self._build()

    @staticmethod
    def from_evaluation(ev: Evaluation, reach: float) -> ElementSet:
        return ElementSet(ev.center, ev.radius, ev.beam_nodes, reach)

    def _element_bounds(self):
        """Per element: lo (E, 3), hi (E, 3); balls first, then beams."""
        c, r = self.center, self.radius
        lo_b, hi_b = c - r[:, None], c + r[:, None]
        a, b = self.beam_nodes[:, 0], self.beam_nodes[:, 1]
        lo_e = np.minimum(lo_b[a], lo_b[b])
        hi_e = np.maximum(hi_b[a], hi_b[b])
        return np.concatenate([lo_b, lo_e]), np.concatenate([hi_b, hi_e])

    def _build(self) -> None:
        n_el = len(self.center) + len(self.beam_nodes)
        self.empty = n_el == 0
        if self.empty:
            return
        lo, hi = self._element_bounds()
        lo, hi = lo - self.reach, hi + self.reach
        self.origin = lo.min(axis=0)
        top = hi.max(axis=0)
        # cell size: about the typical element radius (measured best: docs/filters.md), but never
        # more than ~4M cells overall
        h = max(np.median(self.radius) + self.reach, float(np.prod(top - self.origin) / 4e6) ** (1 / 3), 1e-12)
        while True:  # long thin diagonal beams fill big boxes: coarsen until the candidate cells fit
            dims = np.maximum(np.ceil((top - self.origin) / h).astype(np.int64), 1)
            c0 = np.floor((lo - self.origin) / h).astype(np.int64)
            c1 = np.minimum(np.floor((hi - self.origin) / h).astype(np.int64), dims - 1)
            span = c1 - c0 + 1
            per = span.prod(axis=1)
            if per.sum() <= MAX_CELL_ENTRIES:
                break
            h *= 1.01 * (per.sum() / MAX_CELL_ENTRIES) ** (1 / 3)
        self.h, self.dims = h, dims
        elem = np.repeat(np.arange(n_el), per)
        start = np.repeat(np.cumsum(per) - per, per)
        local = np.arange(len(elem)) - start
        sy, sz = span[elem, 1], span[elem, 2]
        cell = c0[elem] + np.stack([local // (sy * sz), (local // sz) % sy, local % sz], axis=1)
        # drop cells the element cannot reach: conservative test of the cell's bounding ball
        centre = self.origin + (cell + 0.5) * h
        keep = self._hits(elem, centre, np.full(len(elem), 0.5 * math.sqrt(3) * h + self.reach))
        elem, cell = elem[keep], cell[keep]
        key = (cell[:, 0] * self.dims[1] + cell[:, 1]) * self.dims[2] + cell[:, 2]
        order = np.argsort(key, kind="stable")
        self.cell_elem = elem[order]
        self.keys, self.first = np.unique(key[order], return_index=True)
        self.counts = np.diff(np.append(self.first, len(order)))

    def _hits(self, elem: np.ndarray, p: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Exact test of query balls (p, r) against elements ``elem`` (pairwise rows)."""
        nb = len(self.center)
        out = np.empty(len(elem), dtype=bool)
        is_ball = elem < nb
        rows = np.flatnonzero(is_ball)
        e = elem[rows]
        out[rows] = ball_ball_interfere(p[rows], r[rows], self.center[e], self.radius[e])
        rows = np.flatnonzero(~is_ball)
        bn = self.beam_nodes[elem[rows] - nb]
        a, b = bn[:, 0], bn[:, 1]
        out[rows] = ball_beam_interfere(p[rows], r[rows], self.center[a], self.radius[a], self.center[b],
                                        self.radius[b])
        return out

    def any_hit(self, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
        """bool (q,): which query balls interfere with at least one element."""
        centers = np.asarray(centers, dtype=float).reshape(-1, 3)
        radii = np.asarray(radii, dtype=float).reshape(-1)
        out = np.zeros(len(centers), dtype=bool)
        if self.empty or len(centers) == 0:
            return out
        if radii.max() > self.reach * (1 + 1e-9):
            raise PleError(f"query radius {radii.max():.6g} exceeds the element index reach {self.reach:.6g}")
        starts = range(0, len(centers), QUERY_CHUNK)

        def work(s: int) -> None:
            out[s:s + QUERY_CHUNK] = self._any_hit_chunk(centers[s:s + QUERY_CHUNK], radii[s:s + QUERY_CHUNK])

        if len(starts) == 1:
            work(0)
        else:  # numpy releases the GIL in the heavy array operations: chunks run on THREADS threads
            with ThreadPoolExecutor(THREADS) as pool:
                list(pool.map(work, starts))
        return out

    def _any_hit_chunk(self, p: np.ndarray, r: np.ndarray) -> np.ndarray:
        cell = np.floor((p - self.origin) / self.h).astype(np.int64)
        inside = np.all((cell >= 0) & (cell < self.dims), axis=1)
        q = np.flatnonzero(inside)
        c = cell[q]
        key = (c[:, 0] * self.dims[1] + c[:, 1]) * self.dims[2] + c[:, 2]
        pos = np.minimum(np.searchsorted(self.keys, key), len(self.keys) - 1)
        found = self.keys[pos] == key
        q, pos = q[found], pos[found]
        cnt = self.counts[pos]
        query = np.repeat(q, cnt)
        first = np.cumsum(cnt) - cnt
        elem = self.cell_elem[np.repeat(self.first[pos] - first, cnt) + np.arange(len(query))]
        # two passes: each query's first candidate, then the others only for queries not yet hit
        hit = np.zeros(len(p), dtype=bool)
        hit[q] = self._hits(elem[first], p[q], r[q])
        rest = np.ones(len(query), dtype=bool)
        rest[first] = False
        rest &= ~hit[query]
        query, elem = query[rest], elem[rest]
        more = self._hits(elem, p[query], r[query])
        hit[query[more]] = True
        return hit


# ----- Lattice-in-Lattice (thesis §9) ---------------------------------------------------------------
def evaluate_all(coarse) -> Evaluation:
    """All surviving elements of a (filtered) coarse lattice, with a size guard."""
    lat = coarse.lattice if isinstance(coarse, FilteredLattice) else coarse
    if lat.node_count() > MAX_COARSE_NODES:
        raise PleError(f"coarse lattice has {lat.node_count():,} nodes (limit {MAX_COARSE_NODES:,}); "
                       "a LiL coarse lattice is evaluated in full")
    return coarse.evaluate()


class LiL(Filter):
    """Lattice-in-Lattice: a fine node survives when its ball interferes with a ball or a
    cone-beam of ``coarse`` (a Lattice, or a FilteredLattice for cascades, thesis Fig. 9.3).

    ``method``: ``elements`` evaluates the coarse lattice's (surviving) elements and queries a
    grid over them; ``biq`` calls ``ple.biq.any_hit`` (RangeFinder BIQs against an unfiltered
    coarse lattice); ``auto`` picks ``elements``, which measured faster (docs/filters.md)."""

    def __init__(self, coarse, method: str = "auto") -> None:
        if not isinstance(coarse, (Lattice, FilteredLattice)):
            raise PleError(f"LiL coarse must be a Lattice or a FilteredLattice, got {type(coarse).__name__}")
        if method not in ("auto", "elements", "biq"):
            raise PleError(f"LiL method {method!r}: expected auto, elements or biq")
        coarse = with_own_filter(coarse)
        if method == "biq" and isinstance(coarse, FilteredLattice):
            raise PleError("LiL method 'biq' needs an unfiltered coarse lattice (BIQ runs on the program)")
        coarse_lat = coarse.lattice if isinstance(coarse, FilteredLattice) else coarse
        coarse_lat.validate()
        self.coarse = coarse
        self.method = "elements" if method == "auto" else method
        self._index: ElementSet | None = None

    def element_index(self, reach: float) -> ElementSet:
        """The grid over the coarse elements, built once for query radii up to ``reach``."""
        if self._index is None or self._index.reach < reach:
            self._index = ElementSet.from_evaluation(evaluate_all(self.coarse), reach)
        return self._index

    def node_mask(self, lat, node_index, center, radius):
        if len(center) == 0:
            return np.zeros(0, dtype=bool)
        if self.method == "biq":
            from . import biq

            return np.asarray(biq.any_hit(self.coarse, center, radius), dtype=bool)
        reach = max(float(np.max(radius)), max_radius(lat))
        return self.element_index(reach).any_hit(center, radius)


def max_radius(lat: Lattice) -> float:
    """Largest ball radius of the lattice (closed form: the extreme group factors are at the
    corners of the index box, since the factor is s_U**i s_V**j s_W**k)."""
    nu, nv, nw = lat.counts
    f = max(lat.U.factor ** i * lat.V.factor ** j * lat.W.factor ** k
            for i in (0, nu - 1) for j in (0, nv - 1) for k in (0, nw - 1))
    return float(lat.placement.factor * f * lat.template_radii.max())


def with_own_filter(lat):
    """A Lattice carrying a program filter (``Lattice.set_filter``) as a FilteredLattice; anything
    else unchanged."""
    own = getattr(lat, "filter", None)
    if isinstance(lat, Lattice) and own is not None:
        return FilteredLattice(lat, own)
    return lat


def lil(fine: Lattice, *coarse: Lattice, extra: Filter | None = None, method: str = "auto") -> FilteredLattice:
    """Cascaded LiL: ``lil(F, M, C)`` is F filtered by (M filtered by C), finest to coarsest.
    ``extra`` (e.g. a Stencil) is and-ed into the finest level. A program filter carried by any
    of the lattices (``Lattice.set_filter``) is and-ed into its own level."""
    if not coarse:
        raise PleError("LiL needs at least one coarse lattice")
    current: Lattice | FilteredLattice = coarse[-1]
    for medium in reversed(coarse[:-1]):
        current = FilteredLattice(medium, own_and(medium, LiL(current, method="elements")))
    top: Filter = LiL(current, method=method if len(coarse) == 1 else "elements")
    if extra is not None:
        top = _as_filter(extra) & top
    return FilteredLattice(fine, own_and(fine, top))


def own_and(lat: Lattice, f: Filter) -> Filter:
    """``f`` preceded by the lattice's own program filter, if it has one."""
    own = getattr(lat, "filter", None)
    return f if own is None else _as_filter(own) & f


def evaluate_lattice(lat: Lattice, region=None) -> Evaluation:
    """A region's nodes and beams with the lattice's own filter (``Lattice.set_filter``)
    applied when it has one: what every command draws, meshes and writes."""
    if lat.filter is None:
        return lat.evaluate(region)
    return FilteredLattice(lat, lat.filter).evaluate(region)
