"""What a ball-interference query returns (thesis §7): validated query balls and per-query hit
lists; shared by every query backend and the dispatcher in ``ple.queries.biq``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import PleError


@dataclass
class BIQResult:
    """Hits of one query ball: ``nodes`` (n, 4) int64 [i, j, k, n] and ``beams`` (m, 4) int64
    [i, j, k, pattern] (from-group of the beam), both sorted lexicographically; ``path`` is
    the algorithm used ("naive", "1", "u", "uv" or "becots")."""

    nodes: np.ndarray
    beams: np.ndarray
    path: str = "naive"


def check_queries(centers, radii) -> tuple[np.ndarray, np.ndarray]:
    """Validate query balls: centres (q, 3) finite, radii (q,) finite and >= 0."""
    c = np.asarray(centers, dtype=float)
    r = np.asarray(radii, dtype=float)
    if c.ndim == 1 and c.shape == (3,):
        c = c[None]
    if r.ndim == 0:
        r = np.full(len(c), float(r))
    if c.ndim != 2 or c.shape[1] != 3:
        raise PleError(f"query centres: expected shape (q, 3), got {c.shape}")
    if r.shape != (len(c),):
        raise PleError(f"query radii: expected shape ({len(c)},), got {r.shape}")
    if not np.all(np.isfinite(c)):
        raise PleError("query centres: NaN or infinite coordinates")
    if not np.all(np.isfinite(r)):
        raise PleError("query radii: NaN or infinite values")
    if np.any(r < 0):
        raise PleError(f"query radii: must be >= 0, got {float(r.min())}")
    return c, r


class BIQResults(Sequence):
    """The BIQResult of every query ball, over flat hit rows: ``nodes`` (N, 4) and ``beams``
    (M, 4) int64, each query's rows contiguous, sorted and distinct, ``node_ends`` /
    ``beam_ends`` (q,) the end of each query's rows. A query's BIQResult (views of the flat rows)
    is made when it is asked for, so answering many queries costs no Python object per query."""

    __slots__ = ("nodes", "beams", "node_ends", "beam_ends", "path")

    def __init__(self, nodes: np.ndarray, node_ends: np.ndarray, beams: np.ndarray, beam_ends: np.ndarray,
                 path: str):
        self.nodes, self.node_ends, self.beams, self.beam_ends, self.path = nodes, node_ends, beams, beam_ends, path

    def __len__(self) -> int:
        return len(self.node_ends)

    def __getitem__(self, t):
        if isinstance(t, slice):
            return [self[x] for x in range(*t.indices(len(self)))]
        q = len(self)
        if not -q <= t < q:
            raise IndexError(f"query {t} of {q}")
        t %= q
        n0 = self.node_ends[t - 1] if t else 0
        b0 = self.beam_ends[t - 1] if t else 0
        return BIQResult(self.nodes[n0:self.node_ends[t]], self.beams[b0:self.beam_ends[t]], self.path)

    def __iter__(self):
        nb = [0, *self.node_ends.tolist()]
        bb = [0, *self.beam_ends.tolist()]
        for t in range(len(self)):
            yield BIQResult(self.nodes[nb[t]:nb[t + 1]], self.beams[bb[t]:bb[t + 1]], self.path)


def split_hits(q: int, node_hits, beam_hits, path: str) -> BIQResults:
    """Turn hit arrays (qid, i, j, k, x) into per-query sorted BIQResults."""
    parts = []
    for hits in (node_hits, beam_hits):
        hits = _unique_rows(np.asarray(hits, dtype=np.int64).reshape(-1, 5))
        parts.append((np.ascontiguousarray(hits[:, 1:]), np.searchsorted(hits[:, 0], np.arange(1, q + 1))))
    (nh, ne), (bh, be) = parts
    return BIQResults(nh, ne, bh, be, path)


def _unique_rows(hits: np.ndarray) -> np.ndarray:
    """The distinct rows of an int (n, c) array, sorted lexicographically (``np.unique(axis=0)``'s
    answer, by a lexsort of the columns instead of a sort of row records)."""
    if len(hits) < 2:
        return hits
    hits = hits[np.lexsort(hits.T[::-1])]
    fresh = np.ones(len(hits), bool)
    fresh[1:] = (hits[1:] != hits[:-1]).any(axis=1)
    return hits[fresh]
