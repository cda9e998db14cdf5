"""What a ball-interference query returns (thesis §7): validated query balls and per-query hit
lists; shared by every query backend and the dispatcher in ``ple.queries.biq``."""

from __future__ import annotations

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


def split_hits(q: int, node_hits, beam_hits, path: str) -> list[BIQResult]:
    """Turn hit arrays (qid, i, j, k, x) into per-query sorted BIQResults."""
    out = []
    parts = []
    for hits in (node_hits, beam_hits):
        hits = _unique_rows(np.asarray(hits, dtype=np.int64).reshape(-1, 5))
        bounds = np.searchsorted(hits[:, 0], np.arange(q + 1))
        parts.append((hits[:, 1:], bounds))
    (nh, nb), (bh, bb) = parts
    for t in range(q):
        out.append(BIQResult(nh[nb[t]:nb[t + 1]], bh[bb[t]:bb[t + 1]], path))
    return out


def _unique_rows(hits: np.ndarray) -> np.ndarray:
    """The distinct rows of an int (n, c) array, sorted lexicographically (``np.unique(axis=0)``'s
    answer, by a lexsort of the columns instead of a sort of row records)."""
    if len(hits) < 2:
        return hits
    hits = hits[np.lexsort(hits.T[::-1])]
    fresh = np.ones(len(hits), bool)
    fresh[1:] = (hits[1:] != hits[:-1]).any(axis=1)
    return hits[fresh]
