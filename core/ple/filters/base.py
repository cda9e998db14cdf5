"""The filter model of hierarchical lattices (thesis §9): filters, their compounds, filtered evaluation.

A filter decides per node (thesis §9: F(N) -> true/false) from the node's index (i, j, k, n)
and its ball; a beam survives when both of its nodes survive. Filters compose with ``&``,
``|`` and ``~`` and are applied lazily: ``FilteredLattice(lat, f).evaluate(region)`` evaluates
only that region of the lattice. A Lattice-in-Lattice (LiL) filter keeps a fine node when
its ball interferes with a coarse lattice (a ball or a cone-beam of it); the coarse lattice
may itself be a ``FilteredLattice``, which gives the cascades of thesis Fig. 9.3.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod

import numpy as np

from ..errors import PleError
from ..model.lattice import Evaluation, Lattice, Region

MAX_COARSE_NODES = 20_000_000  # a coarse lattice is evaluated in full; beyond this it is not "coarse"
QUERY_CHUNK = 1 << 17  # query balls per vectorized batch (bounds the candidate-pair memory)
THREADS = min(4, os.cpu_count() or 1)
MAX_CELL_ENTRIES = 4_000_000  # (grid cell, element) candidates before the exact reach test


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


def with_own_filter(lat):
    """A Lattice carrying a program filter (``Lattice.set_filter``) as a FilteredLattice; anything
    else unchanged."""
    own = getattr(lat, "filter", None)
    if isinstance(lat, Lattice) and own is not None:
        return FilteredLattice(lat, own)
    return lat


def all_of(*filters) -> Filter | None:
    """The filter keeping what every given filter keeps (None entries are skipped; None if
    none is left): how a program's own filter and the filters added by a command, a LiL
    level or the add-on's panel are composed, left to right."""
    parts = [_as_filter(f) for f in filters if f is not None]
    if not parts:
        return None
    return parts[0] if len(parts) == 1 else And(*parts)


def own_and(lat: Lattice, f: Filter) -> Filter:
    """``f`` preceded by the lattice's own program filter, if it has one."""
    return all_of(getattr(lat, "filter", None), f)


def evaluate_lattice(lat: Lattice, region=None) -> Evaluation:
    """A region's nodes and beams with the lattice's own filter (``Lattice.set_filter``)
    applied when it has one: what every command draws, meshes and writes."""
    if lat.filter is None:
        return lat.evaluate(region)
    return FilteredLattice(lat, lat.filter).evaluate(region)
