"""Meshes that survive their own number format: snap to a float32-exact grid, then weld.

STL, PLY, GLB and 3MF store float32 coordinates. A float64 mesh with edges shorter than
float32's spacing at its coordinates (CHoCC corridors that degenerate to an edge leave such
edges, down to 1e-8) loses them on writing: their two ends become one point, the faces on
them degenerate and the readers see non-manifold edges. Here every vertex is snapped to a
grid whose spacing ``g`` is a power of two at least ``GRID_ULPS`` float32 spacings at the
largest coordinate of the whole lattice region (so every grid point is exactly a float32,
and the snap is the same vertex by vertex in every streamed box). Vertices that land on one
grid point are one vertex (an edge collapse); faces that lose a corner and pairs of opposite
faces on the same three vertices are dropped. Every remaining edge is at least ``g`` long,
written exactly, so the file reads back with the topology checked here.

This module computes; the writers (``ple.io.export``) call it just before writing.
"""

from __future__ import annotations

import numpy as np

GRID_ULPS = 4  # grid spacing in float32 spacings at the largest |coordinate|


def grid_spacing(lo, hi) -> float:
    """The snap grid for coordinates within [lo, hi] (arrays or floats): the smallest power of
    two at least GRID_ULPS float32 spacings at max(|lo|, |hi|)."""
    m = float(np.max(np.abs(np.concatenate([np.ravel(lo), np.ravel(hi)]))))
    ulp = float(np.spacing(np.float32(max(m, 1e-30))))
    return float(2.0 ** np.ceil(np.log2(GRID_ULPS * ulp)))


def snap(vertices: np.ndarray, g: float) -> np.ndarray:
    """Vertices rounded to the grid of spacing ``g`` (float64 values, each exactly a float32)."""
    return np.round(np.asarray(vertices, float) / g) * g


def snap_faces(vertices: np.ndarray, faces: np.ndarray, g: float | None) -> np.ndarray:
    """Triangles (k, 3, 3) float32 of ``vertices[faces]`` snapped to the grid ``g`` (``snap``), without
    those whose corners then coincide: ``snap_triangles`` of ``vertices[faces]``, bit for bit, with the
    rounding done once per vertex rather than once per corner. ``g`` None: no snap (float32 only)."""
    parts = list(snapped_slices(vertices, faces, g, max(1, len(np.asarray(faces).reshape(-1, 3)))))
    return parts[0] if len(parts) == 1 else np.concatenate(parts) if parts else np.zeros((0, 3, 3), np.float32)


def snapped_slices(vertices: np.ndarray, faces: np.ndarray, g: float | None, size: int):
    """``snap_faces`` of ``faces`` in slices of ``size`` faces (float32 triangles, a slice at a
    time): the vertices are snapped once."""
    v = np.asarray(vertices, float).reshape(-1, 3)
    v32 = (snap(v, g) if g is not None else v).astype(np.float32)
    faces = np.asarray(faces).reshape(-1, 3)
    cell = np.dtype((np.void, 12))
    for lo in range(0, len(faces), size):
        tri = v32[faces[lo:lo + size]]
        if g is not None:  # corners equal as floats have equal bits but the sign: only those faces are compared
            c = (tri.view(np.uint32) & np.uint32(0x7FFFFFFF)).view(cell).reshape(-1, 3)
            maybe = np.flatnonzero((c[:, 0] == c[:, 1]) | (c[:, 1] == c[:, 2]) | (c[:, 2] == c[:, 0]))
            if len(maybe):
                drop = maybe[~_distinct_corners(tri[maybe])]
                if len(drop):
                    tri = np.delete(tri, drop, axis=0)
        yield tri


def _distinct_corners(tri: np.ndarray) -> np.ndarray:
    """Which triangles (k, 3, 3) have three pairwise distinct corners."""
    ok = np.any(tri[:, 0] != tri[:, 1], axis=1)
    ok &= np.any(tri[:, 1] != tri[:, 2], axis=1)
    ok &= np.any(tri[:, 2] != tri[:, 0], axis=1)
    return ok


def snap_triangles(triangles: np.ndarray, g: float) -> np.ndarray:
    """Triangles (k, 3, 3) snapped to the grid ``g`` (``snap``), without those whose corners then
    coincide: a streamed box's share of a welded mesh (same grid for every box)."""
    tri = snap(np.asarray(triangles, float).reshape(-1, 3, 3), g)
    ne = [np.any(tri[:, a] != tri[:, b], axis=1) for a, b in ((0, 1), (1, 2), (2, 0))]
    return tri[ne[0] & ne[1] & ne[2]]


def unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.unique(a, axis=0, return_index=True, return_inverse=True, return_counts=True)``
    without its sort of rows as opaque records (one stable ``lexsort`` of the integer columns
    instead, several times faster): (first index of each unique row in lexicographic order,
    inverse (N,), counts)."""
    a = np.asarray(a)
    if len(a) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    a = a.reshape(len(a), -1)
    order = np.lexsort(a.T[::-1])  # stable: the first of equal rows is the earliest
    srt = a[order]
    new = np.ones(len(a), bool)
    new[1:] = np.any(srt[1:] != srt[:-1], axis=1)
    group = np.cumsum(new) - 1
    inverse = np.empty(len(a), np.int64)
    inverse[order] = group
    starts = np.flatnonzero(new)
    return order[starts], inverse, np.diff(np.append(starts, len(a)))


def weld(vertices: np.ndarray, faces: np.ndarray, g: float) -> tuple[np.ndarray, np.ndarray, dict]:
    """Snap ``vertices`` to the grid ``g``, merge those on one grid point, drop faces with a
    repeated corner and pairs of opposite faces on one vertex triple.

    Returns (vertices (V', 3) float64 exactly representable in float32, faces (F', 3),
    stats {"merged_vertices", "dropped_faces"})."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    v = snap(vertices, g)
    if len(v) == 0:
        return v.reshape(0, 3), faces, {"merged_vertices": 0, "dropped_faces": 0}
    key = np.round(v / g).astype(np.int64)
    first, inv, _ = unique_rows(key)
    used = np.zeros(len(first), bool)
    f = inv[faces]
    ok = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    f = f[ok]
    dropped = int((~ok).sum())
    if len(f):  # opposite faces on the same triple (a collapsed sliver tetrahedron) cancel
        srt = np.sort(f, axis=1)
        _, fi, cnt = unique_rows(srt)
        twice = cnt[fi] == 2
        if twice.any():
            keep = np.ones(len(f), bool)
            idx = np.flatnonzero(twice)
            order = idx[np.argsort(fi[idx], kind="stable")]
            a, b = order[0::2], order[1::2]
            opposite = _parity(f[a]) != _parity(f[b])
            keep[a[opposite]] = keep[b[opposite]] = False
            dropped += int((~keep).sum())
            f = f[keep]
    used[f.ravel()] = True
    new_id = np.cumsum(used) - 1
    out_v = v[first[used]]
    return out_v, new_id[f], {"merged_vertices": int(len(v) - len(first)), "dropped_faces": dropped}


def _parity(f: np.ndarray) -> np.ndarray:
    """Orientation class of each face's vertex order relative to its sorted order (0/1)."""
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    inversions = (a > b).astype(int) + (a > c) + (b > c)
    return inversions % 2


def edge_manifold(faces: np.ndarray) -> dict:
    """Topology of a face list: edges used by other than exactly two faces, and whether every
    edge is used once in each direction (closed and consistently oriented)."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    if len(e) and (e.min() < 0 or e.max() >= 3037000499):  # keys a * n + b would overflow int64
        cnt = unique_rows(np.sort(e, axis=1))[2]
        n_directed = len(unique_rows(e)[0])
    else:  # one int64 key per edge: a 1-D sort, not a sort of rows (several times faster)
        n = int(e.max()) + 1 if len(e) else 1
        _, cnt = np.unique(np.minimum(e[:, 0], e[:, 1]) * n + np.maximum(e[:, 0], e[:, 1]), return_counts=True)
        n_directed = len(np.unique(e[:, 0] * n + e[:, 1]))
    return {"bad_edges": int((cnt != 2).sum()),
            "oriented": bool(n_directed == len(e) and np.all(cnt == 2))}


COLLAPSE_GRIDS = 4  # template edges shorter than this many grid spacings (in the world) are collapsed


def collapse_short_edges(vertices: np.ndarray, faces: np.ndarray, rings: list, tol: float,
                         keep: np.ndarray | None = None, rounds: int | None = None,
                         trace: list | None = None) -> tuple[np.ndarray, list, int]:
    """Collapse the edges of a closed patch shorter than ``tol`` (shortest first), each only if
    it passes the link condition (the two vertices share exactly the two opposite vertices of
    the edge's faces), so the result stays an oriented 2-manifold with boundary rings.

    ``rings``: lists of vertex ids (the contact rings; a collapsed ring edge leaves its ring one
    vertex shorter). A vertex on a ring, or marked in ``keep``, survives a collapse with a
    vertex that is not. Vertex ids and positions are unchanged (removed vertices become
    unreferenced). ``rounds``: stop after this many passes over the short edges (default: until
    none is left or none can be collapsed). ``trace``: a list to which each pass appends (its
    edges (E, 2), the indices of its short edges in the order they were tried): every decision
    is combinatorial given those, so a mesh with the same faces whose passes find the same short
    edges in the same order collapses the same way (``follows_trace``). Returns (faces, rings,
    number of collapses)."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    v = np.asarray(vertices, float)
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    length = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
    if tol <= 0 or not np.any(length < tol):
        return faces, rings, 0
    pinned = np.zeros(len(v), bool) if keep is None else np.asarray(keep, bool).copy()
    for r in rings:
        pinned[np.asarray(r, np.int64)] = True
    live = np.ones(len(faces), bool)
    fl = faces.tolist()
    vf: dict[int, set] = {}
    for fi, (a, b, c) in enumerate(fl):
        for x in (a, b, c):
            vf.setdefault(x, set()).add(fi)
    alias = np.arange(len(v))
    ring_edges = set()
    for r in rings:
        r = np.asarray(r, np.int64)
        if len(r) > 1:
            ring_edges |= set(zip(np.minimum(r, np.roll(r, -1)).tolist(), np.maximum(r, np.roll(r, -1)).tolist()))
    ring_of: dict[int, set] = {}
    for ri, r in enumerate(rings):
        for w in np.asarray(r, np.int64).tolist():
            ring_of.setdefault(w, set()).add(ri)
    done = 0
    passes = 0
    while rounds is None or passes < rounds:
        passes += 1
        cur = np.array([fl[i] for i in np.flatnonzero(live)], np.int64).reshape(-1, 3)
        e = sorted_edges(cur, len(v))
        d = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
        short = ordered_short(d, tol)
        if trace is not None:
            trace.append((e, short))
        if not len(short):
            break
        progress = 0
        for x, y in e[short].tolist():  # positions never change: each is still shorter than tol
            if alias[x] != x or alias[y] != y:
                continue
            shared = vf[x] & vf[y]
            if not (len(shared) == 2 or (len(shared) == 1 and (min(x, y), max(x, y)) in ring_edges)):
                continue  # a ring edge has one face here (its other face is the beam strip's)
            nx = {w for f in vf[x] for w in fl[f]} - {x}
            ny = {w for f in vf[y] for w in fl[f]} - {y}
            opp = {w for f in shared for w in fl[f]} - {x, y}
            if nx & ny != opp:
                continue  # link condition fails: collapsing would pinch the surface
            if ring_of.get(x, set()) & ring_of.get(y, set()) and (min(x, y), max(x, y)) not in ring_edges:
                continue  # two vertices of one ring that are not neighbours on it: would pinch the ring
            if pinned[y] and not pinned[x]:
                x, y = y, x
            for f in shared:
                live[f] = False
                for w in fl[f]:
                    vf[w].discard(f)
            for f in vf[y]:
                fl[f] = [x if w == y else w for w in fl[f]]
                vf[x].add(f)
            vf[y] = set()
            alias[y] = x
            ring_of[x] = ring_of.get(x, set()) | ring_of.pop(y, set())
            for p, q in [pq for pq in ring_edges if y in pq]:
                ring_edges.discard((p, q))
                p, q = (x if p == y else p), (x if q == y else q)
                if p != q:
                    ring_edges.add((min(p, q), max(p, q)))
            pinned[x] |= pinned[y]
            progress += 1
        done += progress
        if not progress:
            break
    out = np.array([fl[i] for i in np.flatnonzero(live)], np.int64).reshape(-1, 3)
    while np.any(alias[alias] != alias):
        alias = alias[alias]
    new_rings = []
    for r in rings:
        r = alias[np.asarray(r, np.int64)]
        r = r[np.append(True, r[1:] != r[:-1])]
        while len(r) > 1 and r[-1] == r[0]:
            r = r[:-1]
        new_rings.append(r)
    return out, new_rings, done


def sorted_edges(faces: np.ndarray, n: int) -> np.ndarray:
    """The undirected edges (E, 2) of faces over n vertices, each (low, high) once, in
    lexicographic order: ``np.unique(np.sort(edges, axis=1), axis=0)``, by one int64 key per edge
    (a 1-D sort, several times faster than a sort of rows)."""
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    k = np.unique(np.minimum(e[:, 0], e[:, 1]) * n + np.maximum(e[:, 0], e[:, 1]))
    return np.stack([k // n, k % n], axis=1)


def follows_trace(vertices: np.ndarray, trace: list, tol: float) -> bool:
    """Whether ``collapse_short_edges`` of the same faces at ``vertices`` would take the passes
    of ``trace`` (another mesh's, from its ``trace``): the same short edges, in the same order,
    in every pass. Then it makes the same collapses and returns the same faces and rings."""
    v = np.asarray(vertices, float)
    for e, short in trace:
        if not np.array_equal(ordered_short(np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1), tol), short):
            return False
    return bool(trace)


def ordered_short(lengths: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the edges shorter than ``tol``, shortest first (ties in index order): the order
    ``collapse_short_edges`` tries them in."""
    short = np.flatnonzero(lengths < tol)
    return short[np.argsort(lengths[short], kind="stable")]

