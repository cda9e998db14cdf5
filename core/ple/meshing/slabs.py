"""A cluster too large for one union, cut into slabs: memory bounded by the slab, not the cluster.

A cluster with no free beam (``unions.split`` finds none: thick octets, all-shrunk junctions)
can hold most of a lattice. It is cut by planes normal to its longest axis into slabs of at most
``SLAB_TRIANGLES`` input triangles, and each slab is one manifold3d union:

1. Each ball and beam is a convex solid (``unions.element_hulls``). One that crosses a cut plane
   is clipped there *before* the union: its cap on the plane is the polygon of its own edges cut
   by the plane, computed once per element from its one hull (the same floats on both sides).
2. The slab's clipped elements are united. Its cap on each cut plane is the union of those
   polygons (§3 of the unions' locality: what meets on the plane is what crosses it, on both
   sides the same elements). The cap's vertices are the polygons' corners (the same floats on
   both sides) and their edges' crossings, which the two Booleans compute from different faces:
   the second slab's crossings are matched to the first's (within ``SEAM_TOLERANCE`` of the
   cluster's size, one to one, with the same edges) and take its floats.
3. The caps are removed: the slabs meet along the seam with identical vertices, as the pieces of
   ``unions`` meet the fast path along its rings, and the seams are pinned on the output grid
   (``unclean.on_grid``) as the rings are.

A plane that does not give matching seams (a crossing too close to a corner, a coincidence of a
symmetric lattice) is moved by a fraction of the slab and the slabs are united again, up to
``SEAM_TRIES`` times.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PleError
from .unclean import BALL_TURNS, SPHERE_SEGMENTS, match_rows, on_grid
from .unions import UNION_TRIANGLE_BYTES, element_hulls, manifold3d_module, open_rings, stoppable
from .weld import sorted_edges

SLAB_TRIANGLES = 1_500_000  # input triangles of one slab's union (about 0.9 GB at UNION_TRIANGLE_BYTES)
SEAM_TOLERANCE = 2.0**-32  # of the cluster's size: how far the two slabs' crossings on a seam may lie apart
SEAM_TRIES = 4  # plane positions tried before a cluster is refused
CLEARANCE = 2.0**-20  # of the cluster's size: how far a cut plane stays from every element's vertex


def element_triangles(cluster) -> np.ndarray:
    """Input triangles of each element of a cluster, in ``element_hulls``' order, from above
    (as ``unions.piece_estimate``): a polygonal ball per hub, two balls' worth per beam or half."""
    ball = 2 * SPHERE_SEGMENTS * (SPHERE_SEGMENTS // 2)
    n = len(cluster.hubs), len(cluster.beams), len(cluster.halves)
    return np.concatenate([np.full(n[0], ball), np.full(n[1] + n[2], 2 * ball)]).astype(np.int64)


def element_extents(cluster, center, radius, beam_nodes) -> np.ndarray:
    """(E, 2, 3): each element's box (low, high corner), from its balls' bounding spheres."""
    c, r = np.asarray(center, float), np.asarray(radius, float) * 1.02
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    ends = np.concatenate([np.stack([cluster.hubs, cluster.hubs], 1), bn[cluster.beams],
                           bn[cluster.halves[:, 0]] if len(cluster.halves) else np.zeros((0, 2), np.int64)])
    lo = np.minimum(c[ends[:, 0]] - r[ends[:, 0], None], c[ends[:, 1]] - r[ends[:, 1], None])
    hi = np.maximum(c[ends[:, 0]] + r[ends[:, 0], None], c[ends[:, 1]] + r[ends[:, 1], None])
    return np.stack([lo, hi], axis=1)


def plan_slabs(weights: np.ndarray, extents: np.ndarray, limit: int = SLAB_TRIANGLES):
    """(axis, cuts) for elements of ``weights`` (input triangles) and ``extents`` (E, 2, 3): the
    cluster's longest axis, and planes along it at which no slab holds more than ``limit``
    triangles where that can be had (a slab holds every element that reaches into it); cuts is
    empty when the whole fits. Greedy: each slab grows element by element (in order of their low
    ends) until the next would pass the limit."""
    size = extents[:, 1].max(axis=0) - extents[:, 0].min(axis=0)
    axis = int(np.argmax(size))
    if weights.sum() <= limit:
        return axis, np.zeros(0)
    lo, hi = extents[:, 0, axis], extents[:, 1, axis]
    order = np.argsort(lo, kind="stable")
    cuts, load, start = [], 0, -math.inf
    for i in order:
        if load + weights[i] > limit and lo[i] > start:
            cut = float(lo[i])  # the plane at this element's low end: it and those after go to the next slab
            cuts.append(cut)
            start = cut
            load = int(weights[(hi > cut) & (lo < cut)].sum())  # elements crossing the plane are in both
        load += int(weights[i])
    return axis, np.asarray(cuts, float)


def slab_bytes(cluster, center, radius, beam_nodes, limit: int = SLAB_TRIANGLES) -> int:
    """Peak bytes of a cluster's largest slab union (the whole cluster's when it fits one)."""
    w = element_triangles(cluster)
    ext = element_extents(cluster, center, radius, beam_nodes)
    axis, cuts = plan_slabs(w, ext, limit)
    return int(max(slab_loads(w, ext[:, 0, axis], ext[:, 1, axis], cuts))) * UNION_TRIANGLE_BYTES


def slab_loads(weights, lo, hi, cuts) -> list:
    """Input triangles of each slab between ``cuts`` (every element reaching into it)."""
    edges = [-math.inf, *cuts.tolist(), math.inf]
    return [int(weights[(hi > a) & (lo < b)].sum()) for a, b in zip(edges[:-1], edges[1:])]


def unite_in_slabs(cluster, center, radius, beam_nodes, rings: dict, grid: float, limit: int = SLAB_TRIANGLES):
    """The pieces (vertices, faces) of a cluster cut into slabs (module docstring), each open along
    its seams and along the rings it shares with clean junctions (``unions.unite_cluster``'s
    ``rings``). Tries the balls as they are, then turned (as ``unite_cluster``), each at up to
    ``SEAM_TRIES`` positions of the planes."""
    manifold3d = manifold3d_module()
    weights = element_triangles(cluster)
    ext = element_extents(cluster, center, radius, beam_nodes)
    axis, cuts = plan_slabs(weights, ext, limit)
    if not len(cuts):
        raise PleError("a cluster that fits one union is not cut into slabs")
    lo, hi = ext[:, 0, axis], ext[:, 1, axis]
    gaps = np.diff([lo.min(), *cuts.tolist(), hi.max()])
    last = None
    for turns in (None, BALL_TURNS):
        parts, keys = element_hulls(manifold3d, cluster, center, radius, beam_nodes, rings, turns)
        meshes = [_mesh(p) for p in parts]
        for attempt in range(SEAM_TRIES):
            shift = attempt * 0.13 * np.minimum(gaps[:-1], gaps[1:])  # a fraction of the thinner slab
            at = _clear_planes(cuts + shift, meshes, rings, keys, axis, len(cluster.hubs))
            try:
                return _slabs(manifold3d, parts, meshes, at, axis, rings, keys, grid)
            except PleError as exc:  # a seam that does not match, or a slab the grid folds: move the planes
                last = exc
    raise PleError(f"an unclean cluster of {len(cluster.hubs):,} hubs and {len(cluster.beams):,} beams cut "
                   f"into {len(cuts) + 1} slabs does not join ({last})")


def unite_in_slabs_stoppable(cluster, center, radius, beam_nodes, rings: dict, grid: float) -> list:
    """``unite_in_slabs`` in a child process that a signal stops (``unions.stoppable``)."""
    return stoppable(unite_in_slabs, cluster, center, radius, beam_nodes, rings, grid, SLAB_TRIANGLES)


def _mesh(part) -> tuple[np.ndarray, np.ndarray]:
    m = part.to_mesh64()
    return np.asarray(m.vert_properties[:, :3], float), np.asarray(m.tri_verts, np.int64)


def _clear_planes(cuts, meshes, rings, keys, axis, balls: int = 0) -> np.ndarray:
    """The cut positions moved off the balls (the first ``balls`` meshes: where a beam's hull
    takes a ball's own vertices, two caps would share edges), off every ring (a ring lies within
    one slab) and off every element vertex, by at least ``CLEARANCE`` of the size: each to the
    nearest such position, or off the rings and vertices only where the balls leave none."""
    pts = np.concatenate([v[:, axis] for v, _ in meshes])
    size = float(pts.max() - pts.min()) or 1.0
    clear = CLEARANCE * size
    rings_at = [(float(rings[k][:, axis].min()), float(rings[k][:, axis].max())) for k in keys]
    balls_at = [(float(v[:, axis].min()), float(v[:, axis].max())) for v, _ in meshes[:balls]]
    xs = np.sort(pts)
    out = []
    for c in np.asarray(cuts, float):
        lo, hi = float(xs[0]) + clear, float(xs[-1]) - clear
        free = _nearest_free(c, rings_at + balls_at, clear, lo, hi)
        if free is None:
            free = _nearest_free(c, rings_at, clear, lo, hi)
        c = c if free is None else free
        for _ in range(64):  # step past vertices closer than `clear`
            i = np.searchsorted(xs, c)
            near = xs[max(i - 1, 0):i + 1]
            if not len(near) or np.abs(near - c).min() > clear:
                break
            c += clear
        out.append(c)
    return np.unique(np.asarray(out, float))


def _nearest_free(c: float, blocked: list, clear: float, lo: float, hi: float) -> float | None:
    """The position nearest ``c`` within (lo, hi) outside every interval of ``blocked`` (each
    widened by ``clear``), or None when they cover all of it."""
    iv = sorted((a - clear, b + clear) for a, b in blocked)
    merged: list = []
    for a, b in iv:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    for a, b in merged:
        if a < c < b:
            options = [x for x in (a - clear, b + clear) if lo < x < hi]
            return min(options, key=lambda x: abs(x - c)) if options else None
    return c


def _clip(v: np.ndarray, f: np.ndarray, a: float, b: float, axis: int) -> np.ndarray:
    """The points whose hull is the convex solid (v, f) between the planes ``a`` and ``b`` along
    ``axis``: its vertices between them and its edges' crossings of each plane, each crossing
    computed from the edge's lower-numbered end (so both slabs of a plane get the same floats)."""
    x = v[:, axis]
    keep = v[(x >= a) & (x <= b)]
    e = sorted_edges(f, len(v))
    out = [keep]
    for c in (a, b):
        if not math.isfinite(c):
            continue
        p, q = v[e[:, 0]], v[e[:, 1]]
        cross = (p[:, axis] - c) * (q[:, axis] - c) < 0
        p, q = p[cross], q[cross]
        t = (c - p[:, axis]) / (q[:, axis] - p[:, axis])
        hit = p + t[:, None] * (q - p)
        hit[:, axis] = c
        out.append(hit[_strict_hull(np.delete(hit, axis, axis=1))])
    return np.concatenate(out)


COLLINEAR = 2.0**-34  # of a cap's size: a crossing this close to the chord of its neighbours is no corner


def _strict_hull(p: np.ndarray) -> np.ndarray:
    """Indices of the corners of the convex hull of 2-D points ``p``, without points on (or within
    ``COLLINEAR`` of) the chord of their neighbours: a beam's planar side quad, cut, gives its
    diagonal's crossing on the line of the other two, which a 3-D hull keeps or drops depending
    on the rest of the solid; so a cap polygon is the same on both sides of its plane."""
    if len(p) < 3:
        return np.arange(len(p))
    order = np.lexsort((p[:, 1], p[:, 0]))
    size = float(np.ptp(p, axis=0).max()) or 1.0
    tol = COLLINEAR * size

    def chain(idx):
        out: list = []
        for i in idx:
            while len(out) >= 2:
                a, b = p[out[-2]], p[out[-1]]
                cross = (b[0] - a[0]) * (p[i][1] - a[1]) - (b[1] - a[1]) * (p[i][0] - a[0])
                if cross > tol * np.hypot(p[i][0] - a[0], p[i][1] - a[1]):
                    break
                out.pop()
            out.append(int(i))
        return out

    lower, upper = chain(order), chain(order[::-1])
    return np.asarray(lower[:-1] + upper[:-1], np.int64)


def _slabs(manifold3d, parts, meshes, cuts, axis, rings, keys, grid):
    """Every slab's piece (module docstring), or PleError when a seam does not match."""
    bounds = np.array([[m[0][:, axis].min(), m[0][:, axis].max()] for m in meshes])
    size = float(np.ptp(np.concatenate([m[0] for m in meshes]), axis=0).max()) or 1.0
    tol = SEAM_TOLERANCE * size
    edges = [-math.inf, *cuts.tolist(), math.inf]
    ring_pts = {k: np.asarray(rings[k], float) for k in keys}
    pieces, prev = [], None  # prev: the last slab's high seam, (points (S, 3), edge rows (E, 6))
    for a, b in zip(edges[:-1], edges[1:]):
        inside = np.flatnonzero((bounds[:, 1] > a) & (bounds[:, 0] < b))
        solids = [parts[i] if bounds[i, 0] >= a and bounds[i, 1] <= b
                  else manifold3d.Manifold.hull_points(_clip(*meshes[i], a, b, axis)) for i in inside]
        out = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add).to_mesh64()
        v, f = np.array(out.vert_properties[:, :3], float), np.asarray(out.tri_verts, np.int64)
        low, high = _on_plane(v, a, axis, tol), _on_plane(v, b, axis, tol)
        if prev is not None:  # the seam (the cap's boundary; inner cap vertices go with the cap) takes prev's floats
            v = _matched(v, _boundary(f[low[f].all(axis=1)], len(v)), prev[0], tol)
        seams = [v[low], v[high]]
        own_keys = [k for k in keys if a < ring_pts[k][0, axis] < b]
        pinned = [ring_pts[k] for k in own_keys]
        centre = v.mean(axis=0)
        reach = float(np.linalg.norm(v - centre, axis=1).max())
        v, f = on_grid(v, f, grid, centre[None], reach, rings=pinned + [s for s in seams if len(s)])
        low, high = _rows(v, seams[0]), _rows(v, seams[1])
        caps = (low[f].all(axis=1) & _flat(v, f, a, axis)) | (high[f].all(axis=1) & _flat(v, f, b, axis))
        f = f[~caps]
        open_edges = _open(f, len(v))
        on_low, on_high = low[open_edges].all(axis=1), high[open_edges].all(axis=1)
        if prev is not None and not np.array_equal(_edge_rows(v, open_edges[on_low]), prev[1]):
            raise PleError("a seam between two slabs does not match (its edges differ on the two sides)")
        if pinned:
            v, f = open_rings(v, f, pinned, own_keys, seams=open_edges[on_low | on_high])
        elif not (on_low | on_high).all():
            raise PleError("a slab of an unclean cluster is open off its seams")
        pieces.append((v, f))
        prev = (v[np.unique(open_edges[on_high])], _edge_rows(v, open_edges[on_high]))
    return pieces


def _on_plane(v, c, axis, tol) -> np.ndarray:
    """Vertices on the plane at ``c`` (within ``tol``), put exactly on it."""
    if not math.isfinite(c):
        return np.zeros(len(v), bool)
    on = np.abs(v[:, axis] - c) <= tol
    v[on, axis] = c
    return on


def _flat(v, f, c, axis) -> np.ndarray:
    """Faces lying on the plane at ``c``."""
    return (v[f][:, :, axis] == c).all(axis=1) if math.isfinite(c) else np.zeros(len(f), bool)


def _rows(v, points) -> np.ndarray:
    return match_rows(v, points) >= 0 if len(points) else np.zeros(len(v), bool)


def _open(f, n) -> np.ndarray:
    """Directed edges (E, 2) of ``f`` without their reverse: where the mesh is open."""
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    m = max(n, 1)
    return d[~np.isin(d[:, 0] * m + d[:, 1], d[:, 1] * m + d[:, 0])]


def _edge_rows(v, e) -> np.ndarray:
    """Undirected edges as sorted rows of their two corners' coordinates (E, 6), in order."""
    p, q = v[e[:, 0]], v[e[:, 1]]
    first = _less(p, q)
    rows = np.where(first[:, None], np.concatenate([p, q], axis=1), np.concatenate([q, p], axis=1))
    return rows[np.lexsort(rows.T[::-1])] if len(rows) else rows.reshape(0, 6)


def _less(p, q) -> np.ndarray:
    """Row-wise lexicographic p < q."""
    out = np.zeros(len(p), bool)
    decided = np.zeros(len(p), bool)
    for k in range(3):
        lt, gt = p[:, k] < q[:, k], p[:, k] > q[:, k]
        out |= ~decided & lt
        decided |= lt | gt
    return out


def _boundary(cap: np.ndarray, n: int) -> np.ndarray:
    """(n,) bool: the vertices of a cap's boundary (edges of one cap face only)."""
    out = np.zeros(n, bool)
    out[_open(cap, n).reshape(-1)] = True
    return out


def _matched(v, low, ref, tol) -> np.ndarray:
    """``v`` with the vertices of this slab's low seam replaced by the previous slab's seam
    points ``ref`` (its high plane): one to one within ``tol``; else PleError."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    mine = np.flatnonzero(low)
    if len(mine) != len(ref):
        raise PleError(f"a seam between two slabs has {len(ref)} vertices on one side and {len(mine)} on the other")
    if not len(mine):
        return v
    d, j = cKDTree(ref).query(v[mine])
    if d.max() > tol or len(np.unique(j)) != len(j):
        raise PleError("a seam between two slabs does not match (a crossing moved more than the tolerance)")
    out = v.copy()
    out[mine] = ref[j]
    return out
