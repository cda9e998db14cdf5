"""Baselines the benchmarks time beside PLE, in the same run: what a user without PLE would write.

- ``Elements``: the lattice evaluated once (every node and beam as flat numpy arrays).
- ``naive_hits``: per query ball, the exact test against *every* element, vectorized in numpy
  over all elements (no Python loop over elements; the thesis' naive BIQ, §7.4).
- ``CentreTree`` / ``ElementTree``: a prebuilt ``scipy.spatial.cKDTree`` over the node centres
  (nodes only) or over the node centres and the beam midpoints, asked once for all queries
  (``query_ball_point`` with per-query radii grown by the largest element reach), then the exact
  tests of all candidates vectorized in numpy.

Hits are (qid, row) pairs into the ``Elements`` arrays, comparable with PLE's hits through
``Elements.node_index`` / ``beam_index``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..algebra.elements import ball_ball_interfere, ball_beam_interfere
from ..model.lattice import Lattice


@dataclass
class Elements:
    """Every node ((N, 3) centres, (N,) radii) and beam (end balls (M, 3), (M,) twice) of a
    lattice, with their indices (N, 4) [i, j, k, n] and (M, 4) [i, j, k, pattern]."""

    node_index: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    beam_index: np.ndarray
    ca: np.ndarray
    ra: np.ndarray
    cb: np.ndarray
    rb: np.ndarray

    @classmethod
    def of(cls, lat: Lattice) -> Elements:
        ev = lat.evaluate()
        a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
        return cls(ev.node_index, ev.center, ev.radius, ev.beam_index, ev.center[a], ev.radius[a], ev.center[b],
                   ev.radius[b])


def naive_hits(el: Elements, c: np.ndarray, r: np.ndarray, beams: bool = True):
    """Node hits and beam hits, each (qid, row) int64 (h, 2), of query balls c (q, 3), r (q,):
    every element tested exactly, one query at a time, vectorized over all elements."""
    nodes, beam_hits = [], []
    for t in range(len(c)):
        hit = np.flatnonzero(ball_ball_interfere(el.center, el.radius, c[t], r[t]))
        nodes.append(np.stack([np.full(len(hit), t), hit], axis=1))
        if beams:
            hit = np.flatnonzero(ball_beam_interfere(c[t], r[t], el.ca, el.ra, el.cb, el.rb))
            beam_hits.append(np.stack([np.full(len(hit), t), hit], axis=1))
    cat = lambda parts: np.concatenate(parts) if parts else np.zeros((0, 2), np.int64)  # noqa: E731
    return cat(nodes), cat(beam_hits)


def _candidates(tree: cKDTree, c: np.ndarray, radii: np.ndarray):
    """(qid, point) pairs of every tree point within ``radii`` of each query centre."""
    lists = tree.query_ball_point(c, radii)
    counts = np.fromiter((len(x) for x in lists), np.int64, len(lists))
    rows = np.fromiter((p for x in lists for p in x), np.int64, int(counts.sum()))
    return np.repeat(np.arange(len(c)), counts), rows


class CentreTree:
    """A cKDTree over node centres: node hits of query balls (a node (x, ρ) meets (c, r) iff
    |x - c| <= r + ρ, so the tree is asked with r + the largest ρ)."""

    def __init__(self, el: Elements):
        self.el = el
        self.tree = cKDTree(el.center)
        self.reach = float(el.radius.max())

    def nodes(self, c: np.ndarray, r: np.ndarray) -> np.ndarray:
        qid, row = _candidates(self.tree, c, r + self.reach)
        hit = ball_ball_interfere(self.el.center[row], self.el.radius[row], c[qid], r[qid])
        return np.stack([qid[hit], row[hit]], axis=1)


class ElementTree:
    """A cKDTree over node centres and beam midpoints: a beam lies within half its length plus
    its larger end radius of its midpoint, so the tree is asked with r + the largest such reach."""

    def __init__(self, el: Elements):
        self.el = el
        mid = 0.5 * (el.ca + el.cb)
        reach = 0.5 * np.linalg.norm(el.cb - el.ca, axis=1) + np.maximum(el.ra, el.rb)
        self.tree = cKDTree(np.concatenate([el.center, mid]))
        self.reach = float(max(el.radius.max(), reach.max(initial=0.0)))

    def hits(self, c: np.ndarray, r: np.ndarray):
        """Node hits and beam hits, (qid, row) int64 (h, 2) each."""
        el, nn = self.el, len(self.el.center)
        qid, row = _candidates(self.tree, c, r + self.reach)
        is_node = row < nn
        nq, nr = qid[is_node], row[is_node]
        hit = ball_ball_interfere(el.center[nr], el.radius[nr], c[nq], r[nq])
        node_hits = np.stack([nq[hit], nr[hit]], axis=1)
        bq, br = qid[~is_node], row[~is_node] - nn
        hit = ball_beam_interfere(c[bq], r[bq], el.ca[br], el.ra[br], el.cb[br], el.rb[br])
        return node_hits, np.stack([bq[hit], br[hit]], axis=1)
