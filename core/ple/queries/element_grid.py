"""A uniform grid over explicit balls and cone-beams for batched ``any_hit`` queries (used by
Lattice-in-Lattice filters on evaluated coarse lattices)."""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..algebra.elements import ball_ball_interfere, ball_beam_interfere
from ..errors import PleError
from ..model.lattice import Evaluation

QUERY_CHUNK = 1 << 17  # query balls per vectorized batch (bounds the candidate-pair memory)
THREADS = min(4, os.cpu_count() or 1)
MAX_CELL_ENTRIES = 4_000_000  # (grid cell, element) candidates before the exact reach test


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
