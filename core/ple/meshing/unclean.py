"""Exact meshes of unclean lattices: find the hubs whose junction or beams overlap elements
they are not incident to, mesh everything else on the fast boolean-free path, and unite only
those neighbourhoods robustly with manifold3d.

Clean (ACHoCC, CHoCC paper 001_ §5): every junction lies in its inflated sphere S⁺ (radius
r⁺) and meets only its own beams; every beam, between its two contact disks, meets nothing
but its two junctions. Tested conservatively, per element:

- hub h: the ball (c_h, r⁺_h); beam (a, b): the capsule of radius max(r_a, r_b) around the
  part of its axis outside ``TRIM`` of either end's contact distance;
- unclean: a hub and a hub that are not neighbours, a hub and a beam not incident to it, or two
  beams without a common ball whose volumes overlap; or a hub whose ACHoCC had to shrink its
  contact disks (``HubGeometry.clean`` is False: neighbouring junctions would cross).
- then, when the caller knows the meshes (``points``: the tessellator's placed hub templates and
  beam rings), each pair the spheres flag is tested on the convex hulls of the vertices of the
  two elements' meshes (a hub's junction, a beam's strip between its two contact rings; every
  face lies in the hull of its element's vertices): a plane separating the hulls by more than
  ``margin`` (found by Frank–Wolfe on their Minkowski difference, ``separated``) proves that the
  two meshes cannot meet, even after rounding to the output grid. The spheres S⁺ are loose where
  beams are short and r⁺ large (bent, tapered rows: the warped preset at n = 70 has 6,539
  flagged pairs, all separated; ``ple check`` finds it clean); pairs not proven apart stay unclean.

What is found here is meshed by local unions (``ple.meshing.unions``), each put on the output
grid by ``on_grid``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..algebra.elements import segment_distance
from ..algebra.vectors import runs
from ..errors import PleError
from ..queries.overlaps import incident_keys, non_incident_pairs
from .selfcheck import self_intersections
from .weld import COLLAPSE_GRIDS, edge_manifold, snap, sorted_edges, weld

QUERY_BLOCK = 1 << 19  # elements looked up against the query elements' table at a time (``_query_pairs``)
TRIM = 0.5  # beams are tested from half their contact distance on (the rest is inside S⁺ of their hub)
SPHERE_SEGMENTS = 32  # the fewest segments of a union's polygonal balls (``ball_segments``)
BALL_TURNS = np.array([0.6180339887498949, 0.41421356237309515, 0.7320508075688772])  # golden ratio, √2, √3
# how a union's polygonal balls are turned, tried in this order (``unions.Elements``): as they are;
# all by one turn (BALL_TURNS), which keeps them translates of each other (their beams' hulls stay
# long quads, and copies stay copies) but off the lattice's axes, where cone-beams of a symmetric
# lattice meet tangentially; each its own way (ball x by frac(x · BALL_TURNS)), the last resort
TURN_TRIES = (None, "all", "each")


def ball_segments(segments: int | None = None) -> int:
    """Segments of a local union's polygonal balls (and of its cut rings) for a mesh whose beams
    have ``segments``: as many, a multiple of 4 (manifold3d's spheres are), and never fewer than
    ``SPHERE_SEGMENTS``: 16-segment balls put thin unclean junctions 3 % over the union's volume
    (32: within 1 %). ``SPHERE_SEGMENTS`` for None."""
    if segments is None:
        return SPHERE_SEGMENTS
    return 4 * -(-max(int(segments), SPHERE_SEGMENTS) // 4)


@dataclass
class UncleanReport:
    """Unclean hubs (rows of the evaluation's node arrays) and the overlaps found."""

    nodes: np.ndarray
    pairs: int
    shrunk_hubs: int
    components: int
    close_junctions: int = 0  # neighbouring junctions with pulled-in circles not proven apart
    element_pairs: np.ndarray | None = None  # (P, 2) element ids (hubs 0..N-1, beams N + row) found overlapping
    shrunk: np.ndarray | None = None  # (N,) hubs whose ACHoCC shrank its caps
    clusters: int = 0  # local unions (``ple.meshing.unions``), once the stream has split them
    united: int = 0  # unions made by manifold3d once the stream has settled them (the rest: kept shapes' copies)
    slab_copies: int = 0  # slabs of clusters without free beams copied from a period's (``slabs._Period``)
    union_bytes: int = 0  # the largest cluster's union (its largest slab's), estimated from above (peak bytes)
    union_hubs: int = 0  # that cluster's hubs, beams and overlapping element pairs, and the slabs it is cut into
    union_beams: int = 0
    union_pairs: int = 0
    union_slabs: int = 1
    r_plus: np.ndarray | None = None  # (N,) each hub's S⁺ radius (world units), which holds its junction
    _index: tuple | None = field(default=None, repr=False, compare=False)  # ``pairs_within``'s, made once

    def pairs_within(self, elements: np.ndarray) -> np.ndarray:
        """The element pairs (K, 2) with both ends among ``elements`` (sorted element ids): each
        element's pairs looked up in a directed copy of them sorted once, not a scan of all."""
        if self._index is None:
            p = np.asarray(self.element_pairs if self.element_pairs is not None else np.zeros((0, 2)),
                           np.int64).reshape(-1, 2)
            src, dst = np.concatenate([p[:, 0], p[:, 1]]), np.concatenate([p[:, 1], p[:, 0]])
            order = np.argsort(src, kind="stable")
            self._index = (src[order], dst[order])
        src, dst = self._index
        lo = np.searchsorted(src, elements)
        at = runs(lo, np.searchsorted(src, elements, "right") - lo)
        a, b = src[at], dst[at]
        keep = (a < b) & np.isin(b, elements)
        return np.stack([a[keep], b[keep]], axis=1)

    def paired_beams(self) -> np.ndarray:
        """Rows (sorted) of the beams in some element pair."""
        if self._index is None:
            self.pairs_within(np.zeros(0, np.int64))
        n = len(self.shrunk)
        src = self._index[0]
        return np.unique(src[src >= n] - n)

    def line(self) -> str:
        close = f", {self.close_junctions:,} close junction pairs" if self.close_junctions else ""
        local = f" in {self.clusters:,} local unions" if self.clusters else ""
        if self.clusters and self.united:
            copied = f", {self.slab_copies:,} slabs copied from a period's" if self.slab_copies else ""
            local += f" ({self.united:,} united{copied}, the others copies of those)"
        return (f"unclean lattice: {len(self.nodes):,} hubs in {self.components:,} neighbourhoods "
                f"({self.pairs:,} overlapping element pairs, {self.shrunk_hubs:,} shrunk junctions{close}) "
                f"united with manifold3d{local}")


def find_unclean(center, radius, beam_nodes, r_plus, shrunk=None, points=None, margin: float = 0.0,
                 steady=None, pulled=None, meet=None, twisted=None, farther=None) -> UncleanReport:
    """Unclean hubs of a region from its balls (center (N, 3), radius (N,)), beams (M, 2 rows),
    each hub's inflated radius r_plus (N,) (world units) and ``shrunk`` (N,) hubs whose ACHoCC
    was not clean. ``points(elements)``: for element ids (K,) (hubs 0..N-1, then beams N..N+M-1)
    the vertices (K, P, 3) whose convex hulls hold their meshes; pairs whose hulls lie more than
    ``margin`` apart are clean (``separated``).

    ``steady`` = (node_index (N, 4), a, b, shrink) for a region whose layers k in [a, b) are
    similar copies of each other (a steady lattice along W, §6.1.4: a similarity maps layer k onto
    k + 1, hub templates and all, away from the k borders): only the elements touching a layer
    outside [a, b) and those whose lowest layer is a (the anchors) are looked up against all the
    others; each anchored pair with both elements inside [a, b) stands for its copies shifted up
    by 1, 2, … layers while they stay inside. ``shrink``: the smallest scale of a layer in
    [a, b) relative to layer a (the margin of the anchored hulls is divided by it).

    ``pulled`` (N,): hubs whose short beams pulled contact circles in from S⁺
    (``achocc.pulled_circles``). Their S⁺ reaches past the disks, so the neighbour at the far
    end of each of their beams is no longer kept apart by the ACHoCC: each such pair of
    neighbouring junctions is tested on their hulls too (``points``; without it, unclean). The
    hulls of two such junctions often overlap where their meshes do not (a refined or CNT hub is
    far from convex); ``meet(pairs)`` (P, 2 hub rows) -> (P,) bool, when given, then tells
    from the meshes themselves. ``twisted`` (M,): beams whose strip cannot be zipped (a contact
    ring out of angular order): each is a pair with itself, so a union meshes it."""
    c = np.asarray(center, float).reshape(-1, 3)
    rad = np.asarray(radius, float).reshape(-1)
    rp = np.maximum(np.asarray(r_plus, float).reshape(-1), rad)
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    n, m = len(c), len(bn)
    bad = np.zeros(n, bool) if shrunk is None else np.asarray(shrunk, bool).copy()
    shrunk_count = int(bad.sum())
    # elements: hubs (point, radius r⁺) and beams (trimmed segment, radius max r)
    # written in place (per beam a direction and one product at a time: the check's memory follows
    # its elements, not its temporaries)
    seg0, seg1 = np.empty((n + m, 3)), np.empty((n + m, 3))
    seg0[:n], seg1[:n] = c, c
    np.take(c, bn[:, 0], axis=0, out=seg0[n:])
    np.take(c, bn[:, 1], axis=0, out=seg1[n:])
    u = seg1[n:] - seg0[n:]
    length = np.linalg.norm(u, axis=1)
    u /= np.where(length > 0, length, 1)[:, None]
    ta = TRIM * np.sqrt(np.maximum(rp[bn[:, 0]] ** 2 - rad[bn[:, 0]] ** 2, 0))
    tb = TRIM * np.sqrt(np.maximum(rp[bn[:, 1]] ** 2 - rad[bn[:, 1]] ** 2, 0))
    step = u * ta[:, None]
    seg0[n:] += step
    np.multiply(u, tb[:, None], out=step)
    seg1[n:] -= step
    del u, step, length, ta, tb
    rr = np.concatenate([rp, np.maximum(rad[bn[:, 0]], rad[bn[:, 1]])])
    ends = np.concatenate([np.repeat(np.arange(n)[:, None], 2, axis=1), bn])
    kinds = np.concatenate([np.zeros(n, np.int8), np.ones(m, np.int8)])

    def boxes(rows=slice(None)):  # the elements' bounding boxes, made for the rows searched at a time
        s0, s1, r_ = seg0[rows], seg1[rows], rr[rows, None]
        return np.minimum(s0, s1) - r_, np.maximum(s0, s1) + r_

    anchored = None
    if steady is not None:
        node_index, ka, kb, shrink = steady
        layer = np.asarray(node_index)[:, 2].astype(np.int32)  # per node; its two ends per element
        kmin = np.minimum(layer[ends[:, 0]], layer[ends[:, 1]])
        kmax = np.maximum(layer[ends[:, 0]], layer[ends[:, 1]])
        del layer
        inside = (kmin >= ka) & (kmax < kb)
        anchored = inside & (kmin == ka)
        query = ~inside | anchored
        candidates = _query_pairs(ends, kinds, boxes, bn, query)
    else:
        candidates = non_incident_pairs(ends, kinds, *boxes(), bn)
    # the one candidate search of non-incident elements (``queries.overlaps``), tested here with
    # the junctions' spheres S⁺: elements that share a ball, and hubs joined by a beam, are the
    # junctions' business
    hits = []
    for i, j in candidates:
        hit = segment_distance(seg0[i], seg1[i], seg0[j], seg1[j]) < rr[i] + rr[j]
        if points is not None and hit.any():  # the spheres are loose: test the meshes' hulls
            at = np.flatnonzero(hit)
            copies = np.zeros(len(at), bool) if anchored is None else inside[i[at]] & inside[j[at]]
            for lo_ in range(0, len(at), SEPARATION_CHUNK):
                part = at[lo_:lo_ + SEPARATION_CHUNK]
                # an anchored pair stands for its copies too, the smallest of which is shrink times its size
                far = np.where(copies[lo_:lo_ + SEPARATION_CHUNK], margin / (shrink if anchored is not None else 1.0),
                               margin)
                hit[part[separated(points(i[part]), points(j[part]), far)]] = False
        hits.append(np.sort(np.stack([i[hit], j[hit]], axis=1), axis=1))
    hits = np.unique(np.concatenate(hits), axis=0) if hits else np.zeros((0, 2), np.int64)
    pairs = len(hits)
    bad[ends[hits].reshape(-1)] = True
    found = [hits]
    if anchored is not None and len(hits):
        rep = hits[inside[hits[:, 0]] & inside[hits[:, 1]]]  # anchored: copies up to layer kb - 1
        if len(rep):
            copied = _mark_copies(bad, ends[rep], kmax[rep].max(axis=1), kb, node_index, kinds[rep], bn)
            pairs += len(copied)
            found.append(copied)
    if twisted is not None and np.any(twisted):
        rows = np.flatnonzero(np.asarray(twisted, bool).reshape(-1))
        bad[bn[rows].reshape(-1)] = True
        found.append(np.stack([n + rows, n + rows], axis=1))
        pairs += len(rows)
    close = 0
    if pulled is not None:
        near = _pulled_neighbours(np.asarray(pulled, bool).reshape(-1), bn, points, margin, meet, steady, farther)
        bad[near.reshape(-1)] = True
        close = len(near)
        found.append(near)
    nodes = np.flatnonzero(bad)
    comps = 0
    if len(nodes):
        lab = component_labels(n, bn[bad[bn[:, 0]] & bad[bn[:, 1]]])
        comps = len(np.unique(lab[nodes]))
    shrunk_mask = np.zeros(n, bool) if shrunk is None else np.asarray(shrunk, bool).copy()
    return UncleanReport(nodes, pairs, shrunk_count, comps, close, np.concatenate(found).astype(np.int64),
                         shrunk_mask, r_plus=rp)


def component_labels(n: int, edges) -> np.ndarray:
    """The connected component (a label, (n,)) of each of n nodes joined by ``edges`` (E, 2)."""
    from scipy.sparse import coo_matrix  # noqa: PLC0415 - optional package
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    e = np.asarray(edges, np.int64).reshape(-1, 2)
    return connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)[1]


def _pulled_neighbours(pulled, bn, points, margin: float, meet=None, steady=None, farther=None) -> np.ndarray:
    """Pairs (P, 2) of neighbouring hubs (beams ``bn`` (M, 2) with a ``pulled`` end) whose
    junction hulls are not proven apart (``separated``) and, with ``meet``, whose meshes meet.
    ``steady`` (``find_unclean``'s): a pair inside layers [a, b) whose copy in layer a (its
    anchor) is proven apart by margin / shrink is apart (its hulls are a similar image, at least
    shrink times the size), and so is one whose anchor's meshes are (``farther(pairs, gap)``:
    the placed meshes more than gap apart); only the others are looked at (with ``meet``, the
    copies of an anchor that was not proven apart on their meshes only)."""
    ends = bn[pulled[bn[:, 0]] | pulled[bn[:, 1]]]
    n = np.int64(len(pulled))
    key = np.unique(np.minimum(ends[:, 0], ends[:, 1]) * n + np.maximum(ends[:, 0], ends[:, 1]))
    pairs = np.stack([key // n, key % n], axis=1)
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if points is None or not len(pairs):
        return pairs
    apart = np.zeros(len(pairs), bool)
    todo = np.ones(len(pairs), bool)
    if steady is not None:
        node_index, ka, kb, shrink = steady
        idx = np.asarray(node_index, np.int64)
        layer = idx[:, 2][pairs]
        kmin = layer.min(axis=1)
        inside = (kmin >= ka) & (layer.max(axis=1) < kb)
        anchor = inside & (kmin == ka)
        apart[anchor] = _hulls_apart(pairs[anchor], points, margin / shrink, meet is not None)
        if farther is not None:  # the anchors' meshes, where their hulls overlap (junctions are not convex)
            rest = np.flatnonzero(anchor & ~apart)
            apart[rest] = farther(pairs[rest], margin / shrink)
        copy = np.flatnonzero(inside & (kmin > ka))
        key, step = _layer_keys(idx, kb)
        total = np.int64(key.max() + 1)

        def pair_key(rows, shift):
            return (key[rows[:, 0]] - shift * step) * total + key[rows[:, 1]] - shift * step

        apart[copy] = np.isin(pair_key(pairs[copy], kmin[copy] - ka), pair_key(pairs[anchor & apart], 0))
        # a copy of an anchor whose hulls were not proven apart goes to the mesh test at once (with
        # ``meet``): its hulls are a similar image of the anchor's
        todo = ~inside if meet is not None else ~anchor & ~apart
    rest = np.flatnonzero(todo)
    apart[rest] = _hulls_apart(pairs[rest], points, margin, meet is not None)
    if meet is not None and not apart.all():
        rest = np.flatnonzero(~apart)
        apart[rest] = ~meet(pairs[rest])
    return pairs[~apart]


def _hulls_apart(pairs, points, margin: float, meet: bool = False) -> np.ndarray:
    """Which neighbouring hub pairs (P, 2) have junction hulls (``points``) proven more than
    ``margin`` apart: first across the beam (the plane normal to the line of centres between the
    two disks), then by ``separated`` (fewer steps when the meshes are tested next: ``meet``)."""
    apart = np.zeros(len(pairs), bool)
    for lo in range(0, len(pairs), SEPARATION_CHUNK):
        part = pairs[lo:lo + SEPARATION_CHUNK]
        pa, pb = points(part[:, 0]), points(part[:, 1])
        u = pb.mean(axis=1) - pa.mean(axis=1)
        gap = np.einsum("kpi,ki->kp", pb, u).min(axis=1) - np.einsum("kpi,ki->kp", pa, u).max(axis=1)
        across = gap > margin * np.linalg.norm(u, axis=1)
        rest = np.flatnonzero(~across)
        across[rest] = separated(pa[rest], pb[rest], margin, MEETING_STEPS if meet else SEPARATION_STEPS)
        apart[lo:lo + len(part)] = across
    return apart


def _query_pairs(ends, kinds, boxes, bn, query):
    """Non-incident candidate pairs (blocks of element ids) with at least one element in
    ``query`` (E,) bool: the query elements among themselves, then against all the others (the
    query elements the grid's table, the others looked up QUERY_BLOCK at a time: their boxes
    (``boxes(rows)``), the copies and the grid's temporaries follow the few and one block, not
    the lattice)."""
    q, rest = np.flatnonzero(query), np.flatnonzero(~query)
    keys = incident_keys(ends, bn)
    for i, j in non_incident_pairs(ends[q], kinds[q], *boxes(q), bn, keys=keys):
        yield q[i], q[j]
    for a in range(0, len(rest), QUERY_BLOCK):
        order = np.concatenate([q, rest[a:a + QUERY_BLOCK]])
        for i, j in non_incident_pairs(ends[order], kinds[order], *boxes(order), bn, split=len(q), keys=keys):
            yield order[i], order[j]


def _layer_keys(idx: np.ndarray, kb: int) -> tuple[np.ndarray, np.int64]:
    """Linear keys of node indices (N, 4) (i, j, k, n) with room for layers up to kb, and the key
    step of one layer: a node shifted up by s layers has key + s · step."""
    dims = idx.max(axis=0) + 1
    dims[2] = max(int(dims[2]), kb) + 1
    return ((idx[:, 0] * dims[1] + idx[:, 1]) * dims[2] + idx[:, 2]) * dims[3] + idx[:, 3], np.int64(dims[3])


def _mark_copies(bad, ends, top, kb: int, node_index, kinds, bn) -> np.ndarray:
    """Flag the nodes of the copies of element pairs (P, 2, 2 node rows; ``kinds`` (P, 2): 0 a
    hub, 1 a beam) shifted up by 1, 2, … layers while their highest layer ``top`` (P,) stays
    below kb; returns the copies as element pairs (C, 2) (hubs by node row, beams N + their row
    in ``bn``; a beam copy joins the shifted nodes: every beam between them)."""
    idx = np.asarray(node_index, np.int64)
    n = len(idx)
    key, step = _layer_keys(idx, kb)
    order = np.argsort(key)
    shifts = np.maximum(kb - 1 - np.asarray(top, np.int64), 0)
    rows = np.repeat(ends.reshape(len(ends), -1), shifts, axis=0)  # (copies, 4) node rows
    s = 1 + np.arange(len(rows)) - np.repeat(np.cumsum(shifts) - shifts, shifts)
    k = key[rows] + s[:, None] * step
    at = np.minimum(np.searchsorted(key[order], k), len(key) - 1)
    found = key[order][at] == k
    bad[order[at][found]] = True
    # the copies as elements: hubs are their node, beams the beams between their shifted nodes
    ok = found.all(axis=1)
    shifted = order[at][ok].reshape(-1, 2, 2)
    kind = np.repeat(np.asarray(kinds, np.int64), shifts, axis=0)[ok]
    bkey = bn[:, 0] * n + bn[:, 1]
    border = np.argsort(bkey, kind="stable")
    out = []
    for e in range(2):
        a, b = shifted[:, e, 0], shifted[:, e, 1]
        q = a * n + b
        lo, hi = np.searchsorted(bkey[border], q, "left"), np.searchsorted(bkey[border], q, "right")
        ids = []
        for c in range(len(q)):
            if kind[c, e] == 0:
                ids.append([a[c]])
            else:
                ids.append((n + border[lo[c]:hi[c]]).tolist())
        out.append(ids)
    pairs = [(x, y) for xs, ys in zip(*out) for x in xs for y in ys]
    return np.array(pairs, np.int64).reshape(-1, 2)


SEPARATION_GRIDS = 8  # hulls this many output grid steps apart stay apart after two roundings of each vertex
SEPARATION_STEPS = 64  # Frank–Wolfe steps before a pair is left unclean (warped n = 70: at most 4 needed)
SEPARATION_CHUNK = 4096  # pairs whose vertex sets are held at once
MEETING_STEPS = 16  # Frank–Wolfe steps for neighbouring junctions, whose meshes are tested next (``meet``)


def separated(a, b, margin, steps: int = SEPARATION_STEPS) -> np.ndarray:
    """Which pairs of point sets a (K, P, 3), b (K, Q, 3) have convex hulls lying more than
    ``margin`` apart: a direction x with min(b·x) - max(a·x) > margin |x| is sought by
    Frank–Wolfe steps towards the point of conv(b - a) nearest the origin (support points of the
    Minkowski difference, exact line search). True is a proof (the plane normal to x separates
    them); False means none was found in ``steps`` steps, or the hulls meet (x, a point
    of conv(b - a), is no longer than the margin: they are not that far apart)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    k = len(a)
    margin = np.broadcast_to(np.asarray(margin, float), (k,))
    out = np.zeros(k, bool)
    x = b.mean(axis=1) - a.mean(axis=1)
    live = np.arange(k)
    for _ in range(steps):
        if not len(live):
            break
        xa = x[live]
        pa = np.einsum("kpi,ki->kp", a[live], xa)
        pb = np.einsum("kpi,ki->kp", b[live], xa)
        norm = np.linalg.norm(xa, axis=1)
        ok = pb.min(axis=1) - pa.max(axis=1) > margin[live] * norm
        out[live[ok]] = True
        s = b[live, np.argmin(pb, axis=1)] - a[live, np.argmax(pa, axis=1)]  # support of b - a along -x
        dx = xa - s
        den = np.einsum("ki,ki->k", dx, dx)
        g = np.clip(np.einsum("ki,ki->k", xa, dx) / np.where(den > 0, den, 1.0), 0.0, 1.0)
        x[live] = xa - g[:, None] * dx
        live = live[~ok & (den > 0) & (norm > margin[live])]  # |x| bounds the distance from above
    return out


MAX_REPAIR_ROUNDS = 12


def on_grid(vertices, faces, grid: float, centers, reach: float, rings=None) -> tuple[np.ndarray, np.ndarray]:
    """A closed, self-intersection-free mesh moved onto the float32 grid ``grid`` so that it stays
    so: its edges under ``COLLAPSE_GRIDS`` grid steps are collapsed in 64 bits (link condition),
    the vertices snapped and welded (``ple.meshing.weld.weld``); then, on the faces with a corner within
    ``reach`` of one of ``centers`` (K, 3) (the united parts), while the
    exact check (``ple.meshing.selfcheck``) finds faces that meet when rounded once more, to twice
    the grid (slivers of the Boolean that a rounding tilts: a file in other units, glTF's metres,
    rounds the grid values again), the shortest edge of the thinner face of each pair is collapsed
    onto one of its grid vertices, and so is the shortest edge of every cap flatter than
    ``COLLAPSE_GRIDS`` grid steps. The exact check on the grid has the last word (PleError if it
    finds any pair). Returns (vertices on the grid, faces).
    ``rings``: rings of points (each (k, 3)) that are vertices of the mesh and must stay (a local
    union's rings, shared with the fast path): no collapse removes them, and they come back at
    their own coordinates (on the grid they are where the fast path's writer puts its own). The
    caller removes their polygons (the union is opened along them): faces with every corner on
    one ring are left out of the checks."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    rings = [np.asarray(r, float).reshape(-1, 3) for r in (rings or [])]
    pinned = np.concatenate(rings) if rings else np.zeros((0, 3))
    fixed = _rows_in(v, pinned)
    for _ in range(MAX_REPAIR_ROUNDS):
        e = sorted_edges(f, len(v))
        e = e[np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) < COLLAPSE_GRIDS * grid]
        n = len(f)
        if not len(e) or len(f := collapse_edges(v, f, e, [], fixed)[0]) == n:
            break
    v, f, _ = weld(v, f, grid)
    fixed = _rows_in(v, snap(pinned, grid))
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    tree = cKDTree(np.asarray(centers, float).reshape(-1, 3))
    d, _ = tree.query(v, distance_upper_bound=reach + COLLAPSE_GRIDS * grid)
    keep = np.isfinite(d)[f].any(axis=1)
    if rings:  # the ring polygons go: their faces (slivers once the ring is on the grid) are not checked
        keep &= ~on_one_ring(f, ring_of_vertices(v, [snap(r, grid) for r in rings]))
    near = np.flatnonzero(keep)
    tested = carry = None  # the faces of the last probe and its pairs (vertex id triples)
    for _ in range(MAX_REPAIR_ROUNDS):
        fn = np.sort(f[near], axis=1)
        # the first probe tests every face near the united parts; later ones only those the last
        # round's collapses made (the rest were tested), plus the last pairs still standing
        fresh = None if tested is None else match_rows(fn, tested) < 0
        # a probe: the faces rounded once more, to twice the grid (a file in other units, glTF's
        # metres, rounds the grid values again): faces that fold there are too thin to keep
        probe = near[self_intersections(snap(v, 2 * grid), f[near], fresh)]
        if carry is not None and len(carry):
            at = match_rows(carry.reshape(-1, 3), fn).reshape(-1, 2)
            probe = np.concatenate([probe, near[at[(at >= 0).all(axis=1)]]])
        tested, carry = fn, np.sort(f[probe], axis=2)
        # and caps flatter than the grid, which any rounding may fold onto their neighbours
        t = v[f[near]]
        e = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2)
        flat = near[np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
                    < COLLAPSE_GRIDS * grid * e.max(axis=1)]
        k = np.argmin(np.linalg.norm(v[f[flat][:, [1, 2, 0]]] - v[f[flat]], axis=2), axis=1)
        edges = np.concatenate([_thinner_edges(v, f, probe), np.stack([f[flat, k], f[flat, (k + 1) % 3]], axis=1)])
        n = len(f)
        if len(edges):
            f, near = collapse_edges(v, f, edges, near, fixed)
        if len(f) == n:
            break  # nothing (more) can be collapsed (link condition, flips): the exact check decides
    pairs = near[self_intersections(v, f[near])]
    if len(pairs):
        raise PleError(f"the union of the unclean hubs keeps {len(pairs)} self-intersecting face pairs "
                       "on the float32 grid")
    if edge_manifold(f)["bad_edges"]:
        raise PleError("the union of the unclean hubs is not closed on the float32 grid")
    used = np.unique(f)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    v = v[used]
    if len(pinned):  # back at their own coordinates (the same grid point)
        key = {tuple(q): p for q, p in zip(snap(pinned, grid).tolist(), pinned)}
        for i in np.flatnonzero(_rows_in(v, snap(pinned, grid))):
            v[i] = key[tuple(v[i].tolist())]
    return v, remap[f]


def ring_of_vertices(v: np.ndarray, rings: list) -> np.ndarray:
    """For each vertex (V, 3) the index of the ring (of ``rings``, each (k, 3)) it is a point of
    (exactly), or -1: one search for every ring's points."""
    sizes = [len(r) for r in rings]
    if not sum(sizes):
        return np.full(len(v), -1, np.int64)
    at = match_rows(v, np.concatenate([np.asarray(r, float).reshape(-1, 3) for r in rings]))
    return np.where(at >= 0, np.repeat(np.arange(len(rings)), sizes)[np.maximum(at, 0)], -1)


def on_one_ring(faces: np.ndarray, ring_of: np.ndarray) -> np.ndarray:
    """Which faces (F, 3) have every corner on one ring (``ring_of_vertices``): its polygon."""
    fr = ring_of[faces]
    return (fr[:, 0] >= 0) & (fr[:, 0] == fr[:, 1]) & (fr[:, 1] == fr[:, 2])


def _rows_in(v: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Which rows (V,) of v (V, 3) equal one of ``points`` (K, 3) exactly."""
    if not len(points) or not len(v):
        return np.zeros(len(v), bool)
    return np.isin(_row_view(v), _row_view(points))


def _row_view(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(np.asarray(a, float).reshape(-1, 3)) + 0.0  # -0.0 == 0.0
    return a.view(np.dtype((np.void, 24))).reshape(-1)


def match_rows(rows, table) -> np.ndarray:
    """For each row of ``rows`` (K, 3) the index of an equal row of ``table`` (T, 3), or -1 (of
    equal rows of ``table``, the last). One hash per row (its three 64-bit words mixed), a sorted
    search, then the rows compared; rows whose hash meets another row's are matched by sorting."""
    rows, table = _words(rows), _words(table)
    if not len(rows) or not len(table):
        return np.full(len(rows), -1, np.int64)
    ht, hr = _row_hash(table), _row_hash(rows)
    order = np.argsort(ht, kind="stable")
    hs = ht[order]
    pos = np.searchsorted(hs, hr, side="right") - 1
    cand = order[np.maximum(pos, 0)]
    same_hash = (pos >= 0) & (hs[np.maximum(pos, 0)] == hr)
    equal = same_hash & (table[cand] == rows).all(axis=1)
    out = np.where(equal, cand, -1)
    if (clash := np.flatnonzero(same_hash & ~equal)).size:  # another row with that hash: sort them out
        out[clash] = _match_sorted(rows[clash], table)
    return out


def _words(a) -> np.ndarray:
    """Rows (N, 3) as 64-bit words (floats with -0.0 made 0.0, so that equal floats are equal words)."""
    a = np.asarray(a).reshape(-1, 3)
    a = np.ascontiguousarray(a + 0.0 if a.dtype.kind == "f" else a.astype(np.int64, copy=False))
    return a.view(np.uint64)


_MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9], np.uint64)


def _row_hash(w: np.ndarray) -> np.ndarray:
    h = (w * _MIX) if len(w) else w
    h = h[:, 0] ^ np.left_shift(h[:, 1], np.uint64(21)) ^ np.right_shift(h[:, 1], np.uint64(43)) ^ h[:, 2]
    return h ^ np.right_shift(h, np.uint64(29))


def _match_sorted(rows, table) -> np.ndarray:
    _, inv = np.unique(np.concatenate([table, rows]), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    where = np.full(int(inv.max()) + 1, -1, np.int64)
    where[inv[:len(table)]] = np.arange(len(table))
    return where[inv[len(table):]]


def _thinner_edges(v, f, pairs) -> np.ndarray:
    """For each intersecting face pair, the shortest edge (2 vertex ids) of its face with the
    smaller least altitude (twice the area over the longest edge)."""
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    tri = v[f[pairs]]  # (P, 2, 3, 3)
    e = np.linalg.norm(tri[:, :, [1, 2, 0]] - tri, axis=3)  # edge k runs from corner k to k+1
    area2 = np.linalg.norm(np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0]), axis=2)
    alt = area2 / np.maximum(e.max(axis=2), 1e-300)
    which = np.argmin(alt, axis=1)
    face = pairs[np.arange(len(pairs)), which]
    k = np.argmin(e[np.arange(len(pairs)), which], axis=1)
    return np.stack([f[face, k], f[face, (k + 1) % 3]], axis=1)


def collapse_edges(v, f, edges, near, fixed=None):
    """Collapse ``edges`` (E, 2) of a closed oriented mesh where the link condition holds, each
    onto the one of its two vertices that flips none of the moved faces (never removing a vertex
    of ``fixed`` (V,) bool); collapses of one call
    touch disjoint vertex neighbourhoods (so each one's test holds for all). Returns (faces, the
    face ids ``near`` still standing, renumbered)."""
    f = np.asarray(f, np.int64)
    order = np.argsort(f.ravel(), kind="stable")
    starts = np.searchsorted(f.ravel()[order], np.arange(len(v) + 1))
    fan = lambda x: order[starts[x]:starts[x + 1]] // 3  # noqa: E731 - faces around vertex x
    taken: set = set()
    alias = np.arange(len(v))
    drop: list = []
    edges = np.unique(np.sort(np.asarray(edges, np.int64).reshape(-1, 2), axis=1), axis=0)
    length = np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1)
    for x, y in edges[np.argsort(length, kind="stable")].tolist():
        fx, fy = set(fan(x).tolist()), set(fan(y).tolist())
        ring = {w for t in fx | fy for w in f[t].tolist()}
        if x == y or ring & taken:
            continue
        shared = fx & fy
        nx, ny = {w for t in fx for w in f[t].tolist()} - {x}, {w for t in fy for w in f[t].tolist()} - {y}
        if len(shared) != 2 or nx & ny != {w for t in shared for w in f[t].tolist()} - {x, y}:
            continue  # the link condition fails: the collapse would pinch the surface
        for keep, gone, moved in ((x, y, fy - shared), (y, x, fx - shared)):
            if fixed is not None and fixed[gone]:
                continue
            moved = f[sorted(moved)]
            before = v[moved]
            after = v[np.where(moved == gone, keep, moved)]
            nb = np.cross(before[:, 1] - before[:, 0], before[:, 2] - before[:, 0])
            na = np.cross(after[:, 1] - after[:, 0], after[:, 2] - after[:, 0])
            if np.all(np.einsum("ij,ij->i", nb, na) > 0):
                alias[gone] = keep
                drop.extend(shared)
                taken |= ring
                break
    keep_f = np.ones(len(f), bool)
    keep_f[drop] = False
    renumber = np.cumsum(keep_f) - 1
    near = np.asarray(near, np.int64)
    return alias[f[keep_f]], renumber[near[keep_f[near]]]
