"""Ball-interference queries (BIQ), point membership (PMC) and local distance queries (thesis §7).

``query(lat, centers, radii)`` returns, per query ball, every node and beam of the lattice
that it interferes with (closed sets: touching counts). Two paths give identical hit sets:

- ``"naive"``: exact tests against every element, streamed over slabs (the reference);
- ``"rangefinder"``: candidate index ranges from RangeFinder on steady rows (§7.1–7.3), then
  exact tests on the candidates only. The path taken is recorded on each result: ``"1"``
  (U, V, W commute and their maps are mutually invariant, §7.3.1 O(1) case), ``"u"`` (the
  O(ū) case, per U index), ``"uv"`` (the general algorithm over W-rows) or ``"pullback"``
  (the query pulled back into the base slab, ``ple.queries.pullback``: taken for node hits
  alone on every steady lattice whose slab fits its plan, and for nodes and beams where the
  general case would otherwise loop over W-rows).

``beams=False`` answers node hits only (each result's ``beams`` is empty): no beam is tested
or even found as a candidate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..algebra.elements import ball_ball_interfere, ball_beam_interfere, beam_distance
from ..errors import PleError, echo
from ..model.lattice import Lattice
from . import becots_rangefinder, mobius_rangefinder, pullback
from .hits import BIQResult, BIQResults, check_queries, split_hits
from .rangefinder import cached_plan, lattice_any, lattice_hits

NAIVE_CHUNK = 1 << 21  # element × query tests per vectorized batch of the naive path
NAIVE_QUERY_BATCH = 256


# ----- public API ------------------------------------------------------------------------------
def query(lat: Lattice, centers, radii, method: str = "auto", beams: bool = True) -> Sequence[BIQResult]:
    """Per query ball, the nodes and beams of ``lat`` it interferes with (see module doc);
    with ``beams=False`` the nodes only. A sequence of BIQResult, one per ball (``BIQResults``
    on the steady paths: flat hit rows, each query's result made when read)."""
    c, r = check_queries(centers, radii)
    lat.validate()
    if method not in ("auto", "naive", "rangefinder"):
        raise PleError(f"method {echo(method)}: expected auto, naive or rangefinder")
    if lat.group_map is not None:  # Möbius lattices: the pre-image's RangeFinder where it is exact
        found = _kept(lat, _group_map_hits(lat, c, r, method))
        return found if beams else [BIQResult(x.nodes, x.beams[:0], x.path) for x in found]
    if lat.becots is not None and lat.radius_field is not None:
        method = "naive"  # the BeCOTS RangeFinder knows steady radii only
    if lat.becots is not None and method != "naive":
        return _kept(lat, _nodes_only(becots_rangefinder.query(lat, c, r), beams))
    if method == "naive":
        node_hits, beam_hits = naive_hits(lat, c, r, beams)
        path = "naive"
    elif pullback.fits(lat) and (not beams or cached_plan(lat).path == "uv"):
        return _kept(lat, pullback.query(lat, c, r, beams))
    else:
        node_hits, beam_hits, path = lattice_hits(lat, c, r)
        if not beams:
            beam_hits = beam_hits[:0]
    return _kept(lat, split_hits(len(c), node_hits, beam_hits, path))


def _nodes_only(results: Sequence[BIQResult], beams: bool) -> Sequence[BIQResult]:
    if beams:
        return results
    return [BIQResult(x.nodes, x.beams[:0], x.path) for x in results]


def any_hit(lat: Lattice, centers, radii) -> np.ndarray:
    """bool (q,): does each query ball interfere with any kept ball or beam of ``lat``?"""
    c, r = check_queries(centers, radii)
    lat.validate()
    if (lat.becots is not None or lat.filter is not None or lat.radius_field is not None
            or lat.group_map is not None):
        res = query(lat, c, r)
        if isinstance(res, BIQResults):  # the flat rows: a query has a hit where its rows end later
            return (np.diff(res.node_ends, prepend=0) > 0) | (np.diff(res.beam_ends, prepend=0) > 0)
        return np.array([len(x.nodes) > 0 or len(x.beams) > 0 for x in res], dtype=bool)
    return lattice_any(lat, c, r)


def _group_map_hits(lat: Lattice, c: np.ndarray, r: np.ndarray, method: str) -> Sequence[BIQResult]:
    """Groups placed by a map: the Möbius RangeFinder (``ple.queries.mobius_rangefinder``) where
    its pre-image lattice exists, with the naive path for the queries it leaves; otherwise every
    element is tested, O(elements) per query, and the path names why."""
    pl = None if method == "naive" else mobius_rangefinder.cached_plan(lat)
    if pl is None or pl.pre is None:
        node_hits, beam_hits = naive_hits(lat, c, r)
        why = "" if pl is None else f": {pl.reason}"
        return split_hits(len(c), node_hits, beam_hits, f"naive (group map{why})")
    node_hits, beam_hits, rest, path = mobius_rangefinder.lattice_hits(lat, c, r, pl)
    if rest.any():  # query balls around the inversion centre: tested against every element
        ids = np.flatnonzero(rest)
        nh, bh = naive_hits(lat, c[ids], r[ids])
        nh[:, 0], bh[:, 0] = ids[nh[:, 0]], ids[bh[:, 0]]
        node_hits, beam_hits = np.concatenate([node_hits, nh]), np.concatenate([beam_hits, bh])
    return split_hits(len(c), node_hits, beam_hits, f"mobius ({path})")


def _kept(lat: Lattice, results: Sequence[BIQResult]) -> Sequence[BIQResult]:
    """Hits of a filtered lattice: a node the filter removed is never a hit, nor a beam with a
    removed end (thesis §9); the filter is asked once, for the distinct nodes among all hits of
    all queries. Flat hit rows (``BIQResults``) stay flat."""
    if lat.filter is None or not len(results):
        return results
    if isinstance(results, BIQResults):
        nodes, beams = results.nodes.reshape(-1, 4), results.beams.reshape(-1, 4)
    else:
        nodes = np.concatenate([x.nodes for x in results]).reshape(-1, 4)
        beams = np.concatenate([x.beams for x in results]).reshape(-1, 4)
    pats = np.array([(b.n1, b.n2, *b.offset) for b in lat.beams], dtype=np.int64).reshape(-1, 5)[beams[:, 3]]
    start = np.concatenate([beams[:, :3], pats[:, :1]], axis=1)
    end = np.concatenate([beams[:, :3] + pats[:, 2:], pats[:, 1:2]], axis=1)
    keep = _keeps_distinct(lat, np.concatenate([nodes, start, end]))
    keep_nodes = keep[:len(nodes)]
    keep_beams = keep[len(nodes):len(nodes) + len(beams)] & keep[len(nodes) + len(beams):]
    if isinstance(results, BIQResults):
        node_count = np.concatenate([[0], np.cumsum(keep_nodes)])
        beam_count = np.concatenate([[0], np.cumsum(keep_beams)])
        return BIQResults(results.nodes[keep_nodes], node_count[results.node_ends], results.beams[keep_beams],
                          beam_count[results.beam_ends], results.path)
    out, n0, b0 = [], 0, 0
    for x in results:
        n1, b1 = n0 + len(x.nodes), b0 + len(x.beams)
        out.append(BIQResult(x.nodes[keep_nodes[n0:n1]], x.beams[keep_beams[b0:b1]], x.path))
        n0, b0 = n1, b1
    return out


def _keeps_distinct(lat: Lattice, index: np.ndarray) -> np.ndarray:
    """``lat.keeps`` of the nodes (N, 4), each distinct node asked once (a node is hit by many
    queries, and a filter decides per node)."""
    if len(index) < 2:
        return lat.keeps(index)
    low = index.min(axis=0)
    span = index.max(axis=0) - low + 1
    if np.prod(span.astype(float)) < 2.0**62:  # a mixed-radix key of the rows
        rows = index - low
        key = ((rows[:, 0] * span[1] + rows[:, 1]) * span[2] + rows[:, 2]) * span[3] + rows[:, 3]
        _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    else:
        _, first, inverse = np.unique(index, axis=0, return_index=True, return_inverse=True)
    return lat.keeps(index[first])[inverse.reshape(-1)]


def pmc(lat: Lattice, points) -> np.ndarray:
    """Point membership: bool (q,), is each point inside (or on) some ball or beam?"""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    return any_hit(lat, p, np.zeros(len(p)))


@dataclass
class DistanceResult:
    """Elements within ``r`` of a point and the nearest signed distance among them
    (``inf`` when none is within ``r``; negative inside)."""

    nodes: np.ndarray
    beams: np.ndarray
    distance: float


def distance_query(lat: Lattice, point, r: float) -> DistanceResult:
    """Elements within distance ``r`` of ``point`` and the smallest signed distance to them."""
    p = np.asarray(point, dtype=float).reshape(3)
    c, rr = check_queries(p[None], np.array([float(r)]))
    res = query(lat, c, rr)[0]
    best = np.inf
    if len(res.nodes):
        centers, radii = lat.node_balls(res.nodes)
        best = min(best, float(np.min(np.linalg.norm(centers - p, axis=1) - radii)))
    if len(res.beams):
        a, b = _beam_balls(lat, res.beams)
        best = min(best, float(np.min(beam_distance(p, a[0], a[1], b[0], b[1]))))
    return DistanceResult(res.nodes, res.beams, best)


# ----- helpers shared with the RangeFinder path --------------------------------------------------
def _beam_balls(lat: Lattice, beams: np.ndarray):
    """End balls ((centres, radii), (centres, radii)) of beams given as (m, 4) [i, j, k, p]."""
    beams = np.asarray(beams, dtype=np.int64).reshape(-1, 4)
    pats = np.array([(b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams], dtype=np.int64).reshape(-1, 5)
    pp = pats[beams[:, 3]]
    start = lat.node_balls(np.stack([beams[:, 0], beams[:, 1], beams[:, 2], pp[:, 0]], axis=1))
    end = lat.node_balls(np.stack([beams[:, 0] + pp[:, 2], beams[:, 1] + pp[:, 3], beams[:, 2] + pp[:, 4],
                                   pp[:, 1]], axis=1))
    return start, end


def naive_hits(lat: Lattice, c: np.ndarray, r: np.ndarray, beams: bool = True):
    """Exact tests of every query against every node (and beam), streamed over slabs."""
    if len(c) > NAIVE_QUERY_BATCH:
        parts = [naive_hits(lat, c[s:s + NAIVE_QUERY_BATCH], r[s:s + NAIVE_QUERY_BATCH], beams)
                 for s in range(0, len(c), NAIVE_QUERY_BATCH)]
        shift = lambda h, s: h + np.array([s, 0, 0, 0, 0])  # noqa: E731
        return (np.concatenate([shift(n, s) for (n, _), s in zip(parts, range(0, len(c), NAIVE_QUERY_BATCH))]),
                np.concatenate([shift(b, s) for (_, b), s in zip(parts, range(0, len(c), NAIVE_QUERY_BATCH))]))
    nn = len(lat.nodes)
    node_parts, beam_parts = [], []
    per_slab = max(1, NAIVE_CHUNK // max(1, len(c) * max(nn, len(lat.beams), 1)))
    for reg in lat.iter_slabs(max_groups=per_slab):
        gi, gj, gk = (x.reshape(-1) for x in np.meshgrid(np.arange(reg.i0, reg.i1), np.arange(reg.j0, reg.j1),
                                                          np.arange(reg.k0, reg.k1), indexing="ij"))
        centers, radii = lat.region_balls(reg)
        centers, radii = centers.reshape(-1, nn, 3), radii.reshape(-1, nn)
        for n in range(nn):
            hit = ball_ball_interfere(c[:, None], r[:, None], centers[None, :, n], radii[None, :, n])
            qi, gi_ = np.nonzero(hit)
            node_parts.append(np.stack([qi, gi[gi_], gj[gi_], gk[gi_], np.full_like(qi, n)], axis=1))
        for p in range(len(lat.beams) if beams else 0):
            valid, (ca, ra), (cb, rb) = lat.beams_of_pattern(p, gi, gj, gk)
            if not valid.any():
                continue
            ca, ra, cb, rb = ca[valid], ra[valid], cb[valid], rb[valid]
            hit = ball_beam_interfere(c[:, None], r[:, None], ca[None], ra[None], cb[None], rb[None])
            qi, bi = np.nonzero(hit)
            vi, vj, vk = gi[valid], gj[valid], gk[valid]
            beam_parts.append(np.stack([qi, vi[bi], vj[bi], vk[bi], np.full_like(qi, p)], axis=1))
    cat = lambda parts: np.concatenate(parts) if parts else np.zeros((0, 5), np.int64)  # noqa: E731
    return cat(node_parts), cat(beam_parts)


def naive_any(lat: Lattice, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Reference ``any_hit`` by the naive path."""
    nh, bh = naive_hits(lat, c, r)
    out = np.zeros(len(c), dtype=bool)
    out[nh[:, 0]] = True
    out[bh[:, 0]] = True
    return out
