"""Self-intersections of a triangle mesh, with exact orientation predicates.

A closed mesh that intersects itself counts the overlapping parts twice (slicers, volumes).
``self_intersections`` finds every pair of faces that meet other than in their shared
vertices or edge. Faces without area (a repeated vertex, or three collinear corners, decided
exactly) have no interior and take no part (``degenerate`` finds them).

Two forms give the same pairs (tested): the compiled one (``ple.meshing._selfcheck``, optional,
the GIL released) and numpy:

- broad phase: compiled, a hashed uniform grid (cells grown from ``CELL_MEDIANS`` median face
  widths until a face lies in 3 cells on average), each face in the cells of its box, a long face
  only in those of its slices across its longest axis, buckets shared among threads, every
  pair of faces tested once (in the first cell both lie in) and never stored; numpy, a uniform
  grid (cell size from the median box) over boxes of slices of the faces, candidate pairs sorted
  and deduplicated;
- narrow phase: orientation predicates ``orient3d`` / ``orient2d`` in float64 with a static
  error bound (Shewchuk's filter); the few undecided signs are recomputed exactly (compiled:
  floating-point expansions; numpy: integers, the floats' exact values), so every decision is
  exact.

Pairs without a common vertex intersect (or touch) iff an edge of one meets the other
(non-coplanar), or, coplanar, iff their 2D projections overlap. Pairs with one common vertex
intersect iff the edge opposite that vertex in one meets the other. Pairs with a common edge
intersect iff they are coplanar and on the same side of it (a fold). Two faces on the same three
vertices coincide.
"""

from __future__ import annotations

import os

import numpy as np

from ..algebra.vectors import cross
from ..errors import PleError

try:  # the compiled check (setup.py, optional): the numpy form's pairs, without candidate lists
    from . import _selfcheck as _compiled
except ImportError:  # not built (no C compiler): numpy checks
    _compiled = None

CELL_MEDIANS = 2.0  # the compiled grid's first cell over the median middle extent of the faces' boxes
ERRBOUND = (7.0 + 56.0 * 2.0**-53) * 2.0**-53  # Shewchuk's o3derrboundA
MAX_CELL_PAIRS = 1 << 22
GRID_CELL = 0.5  # grid cell over the median slice size (slices: 2 median face extents long)


def orient3d(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Exact sign (-1, 0, 1) of det[a − d, b − d, c − d] for arrays of points (N, 3): positive
    when d lies below the plane of a, b, c seen counter-clockwise (right-hand rule)."""
    ad, bd, cd = a - d, b - d, c - d
    m1 = bd[:, 1] * cd[:, 2] - bd[:, 2] * cd[:, 1]
    m2 = bd[:, 2] * cd[:, 0] - bd[:, 0] * cd[:, 2]
    m3 = bd[:, 0] * cd[:, 1] - bd[:, 1] * cd[:, 0]
    det = ad[:, 0] * m1 + ad[:, 1] * m2 + ad[:, 2] * m3
    perm = (np.abs(ad[:, 0]) * (np.abs(bd[:, 1] * cd[:, 2]) + np.abs(bd[:, 2] * cd[:, 1]))
            + np.abs(ad[:, 1]) * (np.abs(bd[:, 2] * cd[:, 0]) + np.abs(bd[:, 0] * cd[:, 2]))
            + np.abs(ad[:, 2]) * (np.abs(bd[:, 0] * cd[:, 1]) + np.abs(bd[:, 1] * cd[:, 0])))
    s = np.sign(det).astype(np.int8)
    unsure = np.flatnonzero(np.abs(det) <= ERRBOUND * perm)
    if len(unsure):
        s[unsure] = _exact_orient(a[unsure], b[unsure], c[unsure], d[unsure])
    return s


def _exact_integers(x: np.ndarray) -> np.ndarray:
    """Rows of floats (k, m) as Python integers scaled by one power of two per row (exact)."""
    mant, ex = np.frexp(x)
    mi = (mant * 2.0**53).astype(np.int64).astype(object)
    ex = ex.astype(np.int64) - 53
    ex[mant == 0] = np.iinfo(np.int64).max
    shift = ex - ex.min(axis=1, keepdims=True)
    shift[mant == 0] = 0
    return mi << shift.astype(object)


def _exact_orient(a, b, c, d) -> np.ndarray:
    """orient3d signs computed with integers (the floats' exact values, one scale per row)."""
    x = _exact_integers(np.concatenate([a, b, c, d], axis=1))
    a, b, c, d = x[:, 0:3], x[:, 3:6], x[:, 6:9], x[:, 9:12]
    ad, bd, cd = a - d, b - d, c - d
    det = (ad[:, 0] * (bd[:, 1] * cd[:, 2] - bd[:, 2] * cd[:, 1])
           + ad[:, 1] * (bd[:, 2] * cd[:, 0] - bd[:, 0] * cd[:, 2])
           + ad[:, 2] * (bd[:, 0] * cd[:, 1] - bd[:, 1] * cd[:, 0]))
    return np.array([(v > 0) - (v < 0) for v in det], np.int8)


def _orient2d(a, b, c) -> np.ndarray:
    det = (a[:, 0] - c[:, 0]) * (b[:, 1] - c[:, 1]) - (a[:, 1] - c[:, 1]) * (b[:, 0] - c[:, 0])
    perm = np.abs((a[:, 0] - c[:, 0]) * (b[:, 1] - c[:, 1])) + np.abs((a[:, 1] - c[:, 1]) * (b[:, 0] - c[:, 0]))
    s = np.sign(det).astype(np.int8)
    k = np.flatnonzero(np.abs(det) <= 4 * 2.0**-53 * perm)
    if len(k):
        x = _exact_integers(np.concatenate([a[k], b[k], c[k]], axis=1))
        e = (x[:, 0] - x[:, 4]) * (x[:, 3] - x[:, 5]) - (x[:, 1] - x[:, 5]) * (x[:, 2] - x[:, 4])
        s[k] = np.array([(v > 0) - (v < 0) for v in e], np.int8)
    return s


def _pieces(tri: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes covering each triangle (k, 3, 3) in slices across its length: slice i of a triangle
    with apex a (opposite its shortest edge bc) is the hull of a + s(b − a), a + s(c − a) for s in
    [i/m, (i+1)/m], m = ⌈longest edge / h⌉. Returns (face id, box lo, box hi) per slice: a needle
    (a beam strip's triangle) gets small boxes along its length instead of one box across it."""
    e = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)  # edge k runs from corner k to k+1
    short = np.argmin(e, axis=1)
    apex = tri[np.arange(len(tri)), (short + 2) % 3]
    b = tri[np.arange(len(tri)), short] - apex
    c = tri[np.arange(len(tri)), (short + 1) % 3] - apex
    m = np.maximum(np.ceil(e.max(axis=1) / h), 1).astype(np.int64)
    face = np.repeat(np.arange(len(tri)), m)
    i = np.arange(len(face)) - np.repeat(np.cumsum(m) - m, m)
    s0, s1 = (i / m[face])[:, None], ((i + 1) / m[face])[:, None]
    a, b, c = apex[face], b[face], c[face]
    pts = np.stack([a + s0 * b, a + s0 * c, a + s1 * b, a + s1 * c], axis=1)
    return face, pts.min(axis=1), pts.max(axis=1)


def candidate_pairs(tri: np.ndarray, fresh: np.ndarray | None = None) -> np.ndarray:
    """Pairs (P, 2) of face ids (i < j) whose slices' boxes (``_pieces``) overlap: every pair of
    faces that meets, found with a uniform grid over the slices. With ``fresh`` (F,) bool, only
    pairs with a fresh face (cells holding none are skipped)."""
    n = len(tri)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    ext = (tri.max(axis=1) - tri.min(axis=1)).max(axis=1)
    h = max(float(np.median(ext)) * 2.0, 1e-12)
    face, lo, hi = _pieces(tri, h)
    # cells of half the median slice: clusters of small faces (a hub) beside long ones stay sparse
    h = max(float(np.median(np.max(hi - lo, axis=1))) * GRID_CELL, 1e-12)
    origin = lo.min(axis=0)
    clo = np.floor((lo - origin) / h).astype(np.int64)
    chi = np.floor((hi - origin) / h).astype(np.int64)
    span = chi - clo + 1
    cnt = span.prod(axis=1)
    ids = np.repeat(np.arange(len(face)), cnt)
    k = np.arange(len(ids)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    sy, sz = span[ids, 1], span[ids, 2]
    cx = clo[ids, 0] + k // (sy * sz)
    cy = clo[ids, 1] + (k // sz) % sy
    cz = clo[ids, 2] + k % sz
    dims = chi.max(axis=0) + 1
    cell = (cx * dims[1] + cy) * dims[2] + cz
    order = np.argsort(cell, kind="stable")
    cell, ids = cell[order], ids[order]
    if fresh is not None:  # only the cells where a fresh face lies
        starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
        has = np.maximum.reduceat(np.asarray(fresh, bool)[face[ids]], starts)
        keep = np.repeat(has, np.diff(np.r_[starts, len(cell)]))
        cell, ids = cell[keep], ids[keep]
        if not len(cell):
            return np.zeros((0, 2), np.int64)
    starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])
    sizes = np.diff(np.r_[starts, len(cell)])
    cell_of = np.repeat(np.arange(len(starts)), sizes)
    follow = sizes[cell_of] - 1 - (np.arange(len(cell)) - starts[cell_of])  # later entries of the same cell
    out = []
    cum = np.cumsum(follow)
    cuts = np.searchsorted(cum, np.arange(MAX_CELL_PAIRS, int(cum[-1]) + MAX_CELL_PAIRS, MAX_CELL_PAIRS))
    lo_e = 0
    for hi_e in np.unique(np.r_[np.minimum(cuts + 1, len(cell)), len(cell)]):
        fo = follow[lo_e:hi_e]
        first = np.repeat(np.arange(lo_e, hi_e), fo)
        second = first + 1 + np.arange(len(first)) - np.repeat(np.cumsum(fo) - fo, fo)
        lo_e = hi_e
        a, b2 = ids[first], ids[second]
        fa, fb = face[a], face[b2]
        ok = (fa != fb) & np.all((lo[a] <= hi[b2]) & (lo[b2] <= hi[a]), axis=1)
        if fresh is not None:
            ok &= fresh[fa] | fresh[fb]
        out.append(np.stack([np.minimum(fa, fb)[ok], np.maximum(fa, fb)[ok]], axis=1))
    if not out:
        return np.zeros((0, 2), np.int64)
    p = np.concatenate(out)
    key = np.unique(p[:, 0] * n + p[:, 1])
    return np.stack([key // n, key % n], axis=1)


def _seg_tri(p, q, a, b, c) -> np.ndarray:
    """Closed segment pq meets closed (non-degenerate) triangle abc."""
    dp, dq = orient3d(a, b, c, p), orient3d(a, b, c, q)
    inplane = (dp == 0) & (dq == 0)
    crosses = (dp * dq <= 0) & ~inplane
    s1 = orient3d(p, q, a, b)
    s2 = orient3d(p, q, b, c)
    s3 = orient3d(p, q, c, a)
    same = ((s1 >= 0) & (s2 >= 0) & (s3 >= 0)) | ((s1 <= 0) & (s2 <= 0) & (s3 <= 0))
    hit = crosses & same
    k = np.flatnonzero(inplane)
    if len(k):
        hit[k] = _seg_tri_2d(p[k], q[k], a[k], b[k], c[k])
    return hit


def _seg_tri_2d(p, q, a, b, c) -> np.ndarray:
    """Closed segment pq meets closed triangle abc, all in one plane."""
    t = np.stack([a, b, c], axis=1)
    u, w = _project(t, np.stack([p, q], axis=1), cross(b - a, c - a))
    hit = np.zeros(len(p), bool)
    for j in range(3):
        s, e = u[:, j], u[:, (j + 1) % 3]
        o1, o2 = _orient2d(s, e, w[:, 0]), _orient2d(s, e, w[:, 1])
        o3, o4 = _orient2d(w[:, 0], w[:, 1], s), _orient2d(w[:, 0], w[:, 1], e)
        hit |= (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~((o1 == 0) & (o2 == 0) & (o3 == 0) & (o4 == 0))
    for i in range(2):
        o = [_orient2d(u[:, k], u[:, (k + 1) % 3], w[:, i]) for k in range(3)]
        hit |= ((o[0] >= 0) & (o[1] >= 0) & (o[2] >= 0)) | ((o[0] <= 0) & (o[1] <= 0) & (o[2] <= 0))
    return hit


def _project(t1, t2, normal):
    """Drop the dominant axis of ``normal``: 2D copies of point sets t1 (N, k, 3), t2 (N, m, 3)."""
    keep = np.array([[1, 2], [0, 2], [0, 1]])[np.argmax(np.abs(normal), axis=1)]
    pick = lambda t: np.stack([np.take_along_axis(t, keep[:, None, i:i + 1].repeat(t.shape[1], 1), 2)[..., 0]  # noqa: E731
                               for i in (0, 1)], axis=2)
    return pick(t1), pick(t2)


def _coplanar_overlap(t1: np.ndarray, t2: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Closed coplanar triangles (N, 3, 3) overlap, tested in the projection along the dominant
    axis of ``normal``: an edge crossing, or a vertex of one inside the other."""
    u, w = _project(t1, t2, normal)
    hit = np.zeros(len(t1), bool)
    for i in range(3):
        for j in range(3):
            p, q = u[:, i], u[:, (i + 1) % 3]
            s, t = w[:, j], w[:, (j + 1) % 3]
            o1, o2 = _orient2d(p, q, s), _orient2d(p, q, t)
            o3, o4 = _orient2d(s, t, p), _orient2d(s, t, q)
            hit |= (o1 * o2 < 0) & (o3 * o4 < 0)
    for x, y in ((u, w), (w, u)):
        for i in range(3):
            o = [_orient2d(y[:, k], y[:, (k + 1) % 3], x[:, i]) for k in range(3)]
            hit |= ((o[0] >= 0) & (o[1] >= 0) & (o[2] >= 0)) | ((o[0] <= 0) & (o[1] <= 0) & (o[2] <= 0))
    return hit


def self_intersections(vertices, faces, fresh=None, *, workers: int | None = None,
                       cell: float | None = None, sides=None) -> np.ndarray:
    """Pairs (P, 2) int64 of faces (i < j, sorted) that intersect other than in their shared
    vertices or edge, for vertices (V, 3) and faces (F, 3) (vertex ids: faces share a vertex when
    they share its id). Faces without area (``degenerate``) are ignored. ``fresh`` (F,)
    bool: only pairs with at least one fresh face (the others are known apart). ``workers``:
    threads of the compiled form (default: the cores, one per 10⁵ faces; the same pairs for any
    number). ``cell``: the search grid's first cell (``search_cell``), when the caller knows it
    (a copy of a checked mesh). ``sides`` (F,) bool: only pairs of faces on different sides (two
    meshes against each other, each known free of its own intersections); not with ``fresh``."""
    v = np.ascontiguousarray(vertices, float).reshape(-1, 3)
    f = np.ascontiguousarray(faces, np.int64).reshape(-1, 3)
    fresh = None if fresh is None else np.ascontiguousarray(fresh, bool).reshape(-1)
    finite = np.isfinite(v).all(axis=1)
    if not finite.all() and not finite[f].all():
        raise PleError("self-intersections: a face has a non-finite vertex coordinate")
    if sides is not None:
        if fresh is not None:
            raise ValueError("self_intersections: fresh and sides together")
        sides = np.ascontiguousarray(sides, bool).reshape(-1)
    if _compiled is None:
        pairs = _numpy_pairs(v, f, fresh)
        return pairs if sides is None else pairs[sides[pairs[:, 0]] != sides[pairs[:, 1]]]
    if len(f) < 2:
        return np.zeros((0, 2), np.int64)
    if workers is None:
        workers = min(os.cpu_count() or 1, 1 + len(f) // 100_000)
    cell = search_cell(v, f) if cell is None else float(cell)
    apart = sides is not None
    raw, _ = _compiled.pairs(v, f, sides if apart else fresh, cell, max(1, int(workers)), int(apart))
    pairs = np.frombuffer(raw, np.int64).reshape(-1, 2)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def search_cell(v: np.ndarray, f: np.ndarray) -> float:
    """The compiled grid's first cell (it grows until the faces lie in few cells each):
    ``CELL_MEDIANS`` median middle extents of the faces' boxes (the width of a needle, the size of
    a compact face), from a sample of at most 2·10⁴ faces."""
    step = max(1, len(f) // 20_000)
    t = v[f[::step]]
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    ext = np.maximum(np.maximum(a, b), c) - np.minimum(np.minimum(a, b), c)  # (k, 3): the box's sides
    x, y, z = ext[:, 0], ext[:, 1], ext[:, 2]
    ext = x + y + z - np.maximum(np.maximum(x, y), z) - np.minimum(np.minimum(x, y), z)  # the middle one
    return max(float(np.median(ext)) * CELL_MEDIANS, float(np.abs(v).max(initial=0.0)) * 2.0**-40, 1e-300)


def degenerate(vertices, faces) -> np.ndarray:
    """(F,) bool: faces without area, a repeated vertex or three collinear corners (exact: every
    projection of the face onto a coordinate plane has orientation 0)."""
    v = np.ascontiguousarray(vertices, float).reshape(-1, 3)
    f = np.ascontiguousarray(faces, np.int64).reshape(-1, 3)
    if _compiled is not None:
        return np.frombuffer(_compiled.flat(v, f), bool).copy()
    out = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
    k = np.flatnonzero(~out)
    flat = np.ones(len(k), bool)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        a, b, c = (v[f[k, m]][:, [i, j]] for m in range(3))
        flat &= _orient2d(a, b, c) == 0
    out[k[flat]] = True
    return out


def _numpy_pairs(v: np.ndarray, f: np.ndarray, fresh: np.ndarray | None) -> np.ndarray:
    """``self_intersections`` by numpy (candidate pairs listed, then tested by kind)."""
    keep = ~degenerate(v, f)
    idx = np.flatnonzero(keep)
    f = f[idx]
    tri = v[f]
    pairs = candidate_pairs(tri, None if fresh is None else fresh[idx])
    if not len(pairs):
        return pairs
    fa, fb = f[pairs[:, 0]], f[pairs[:, 1]]
    shared = (fa[:, :, None] == fb[:, None, :])
    ns = shared.any(axis=2).sum(axis=1)
    bad = ns == 3  # the same three vertices: the faces coincide
    # no shared vertex
    sel = np.flatnonzero(ns == 0)
    if len(sel):
        bad[sel] = _disjoint_pairs(tri[pairs[sel, 0]], tri[pairs[sel, 1]])
    # one shared vertex: rotate both so the shared vertex comes first
    sel = np.flatnonzero(ns == 1)
    if len(sel):
        sh = shared[sel]
        ia = np.argmax(sh.any(axis=2), axis=1)
        ib = np.argmax(sh.any(axis=1), axis=1)
        t1 = _rotate(tri[pairs[sel, 0]], ia)
        t2 = _rotate(tri[pairs[sel, 1]], ib)
        bad[sel] = (_seg_tri(t1[:, 1], t1[:, 2], t2[:, 0], t2[:, 1], t2[:, 2])
                    | _seg_tri(t2[:, 1], t2[:, 2], t1[:, 0], t1[:, 1], t1[:, 2]))
    # one shared edge: a fold if the far vertex lies in the other's plane on the same side
    sel = np.flatnonzero(ns == 2)
    if len(sel):
        sh = shared[sel]
        ia = np.argmin(sh.any(axis=2), axis=1)  # the unshared vertex of face a
        ib = np.argmin(sh.any(axis=1), axis=1)
        t1 = _rotate(tri[pairs[sel, 0]], ia)  # (a, v, w)
        t2 = _rotate(tri[pairs[sel, 1]], ib)  # (p, ., .)
        copl = orient3d(t1[:, 0], t1[:, 1], t1[:, 2], t2[:, 0]) == 0
        c = np.flatnonzero(copl)
        if len(c):
            n = cross(t1[c, 1] - t1[c, 0], t1[c, 2] - t1[c, 0])
            u, w = _project(t1[c], t2[c, :1], n)
            sa = _orient2d(u[:, 1], u[:, 2], u[:, 0])
            sp = _orient2d(u[:, 1], u[:, 2], w[:, 0])
            bad[sel[c]] = sa * sp > 0
    return idx[pairs[bad]]


def _rotate(t: np.ndarray, first: np.ndarray) -> np.ndarray:
    idx = (first[:, None] + np.arange(3)) % 3
    return np.take_along_axis(t, idx[:, :, None].repeat(3, 2), 1)


def _disjoint_pairs(t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    a, b, c = t1[:, 0], t1[:, 1], t1[:, 2]
    p, q, r = t2[:, 0], t2[:, 1], t2[:, 2]
    dp, dq, dr = orient3d(a, b, c, p), orient3d(a, b, c, q), orient3d(a, b, c, r)
    hit = np.zeros(len(t1), bool)
    maybe = ~(((dp > 0) & (dq > 0) & (dr > 0)) | ((dp < 0) & (dq < 0) & (dr < 0)))
    copl = maybe & (dp == 0) & (dq == 0) & (dr == 0)
    if copl.any():
        c_ = np.flatnonzero(copl)
        hit[c_] = _coplanar_overlap(t1[c_], t2[c_], cross(b[c_] - a[c_], c[c_] - a[c_]))
    m = np.flatnonzero(maybe & ~copl)
    if len(m):
        P, Q, R = p[m], q[m], r[m]
        da, db, dc = orient3d(P, Q, R, a[m]), orient3d(P, Q, R, b[m]), orient3d(P, Q, R, c[m])
        m2 = ~(((da > 0) & (db > 0) & (dc > 0)) | ((da < 0) & (db < 0) & (dc < 0)))
        m = m[m2]
        A, B, C, P, Q, R = a[m], b[m], c[m], p[m], q[m], r[m]
        h = (_seg_tri(P, Q, A, B, C) | _seg_tri(Q, R, A, B, C) | _seg_tri(R, P, A, B, C)
             | _seg_tri(A, B, P, Q, R) | _seg_tri(B, C, P, Q, R) | _seg_tri(C, A, P, Q, R))
        hit[m] = h
    return hit


def count_self_intersections(vertices, faces) -> dict:
    """Intersecting face pairs, the number of faces involved, and the faces without area (which
    take no part)."""
    pairs = self_intersections(vertices, faces)
    return {"self_intersecting_pairs": int(len(pairs)), "self_intersecting_faces": int(len(np.unique(pairs))),
            "degenerate_faces": int(degenerate(vertices, faces).sum())}


BLOCK_TRIANGLES = 1 << 20  # triangles per block of ``check_triangles`` (about 0.3 GB while checked)


def check_triangles(read, block: int = BLOCK_TRIANGLES, store=None) -> dict:
    """Watertightness, winding, Euler characteristic, exact self-intersections and volume of a
    triangle soup read in chunks, as a consumer sees it (corners with equal coordinates are one
    vertex), with memory bounded by ``block`` triangles whatever the soup's size.

    ``read()`` returns a new iterator over chunks of triangles (k, 3, 3) (float32 or float64); it
    is called twice (bounds, then the blocks). Soups of at most ``block`` triangles are checked in
    memory. Larger ones are cut into blocks of a uniform grid over their box: a triangle goes to
    every block its box meets, its record kept by ``store`` until the block is checked
    (``put(key, records)``, ``take(key)``, ``keys()``; default ``MemoryBlocks``, in memory;
    ``ple.io.spill.SpillFiles`` keeps them on disk, so only one block is in memory), and each
    block is welded and checked alone. What spans blocks is counted once, by an owner that sees
    all of it: a vertex by its block; an edge by the block of its lexicographically smaller end
    (every face on the edge has that end in its box); a face by the block of its box's low
    corner; a pair of faces by the block of the low corner of their boxes' intersection (which
    lies in both boxes).

    Returns {"triangles", "watertight" (every edge on exactly two faces), "winding_consistent"
    (and they run it in opposite directions), "euler_characteristic" (V − E + F), "volume"
    (signed, from the divergence theorem), "self_intersecting_pairs", "self_intersecting_faces",
    "degenerate_faces" (``degenerate``), "blocks"}."""
    count, lo, hi = 0, np.full(3, np.inf), np.full(3, -np.inf)
    chunks, single = [], True  # single: every chunk float32 (an STL's), kept as such
    for t in read():
        t = np.asarray(t).reshape(-1, 3, 3)
        single &= t.dtype == np.float32
        if len(t):
            lo, hi = np.minimum(lo, t.min(axis=(0, 1))), np.maximum(hi, t.max(axis=(0, 1)))
        if count + len(t) <= block:
            chunks.append(np.asarray(t, float))
        count += len(t)
    acc = _Tally()
    if count <= block:  # one block: in memory
        tri = np.concatenate(chunks) if chunks else np.zeros((0, 3, 3))
        acc.add(tri, np.arange(len(tri)), None)
        return acc.report(count, 1)
    del chunks
    store = MemoryBlocks() if store is None else store
    grid = _BlockGrid(lo, hi, count, block)
    record = np.dtype([("index", "<i8"), ("corners", "<f4" if single else "<f8", (3, 3))])
    first = 0
    for t in read():
        t = np.asarray(t).reshape(-1, 3, 3)
        rec = np.empty(len(t), record)
        rec["index"], rec["corners"] = np.arange(first, first + len(t)), t
        first += len(t)
        for key, rows in grid.spread(grid.cells(t.min(axis=1)), grid.cells(t.max(axis=1))):
            store.put(key, rec[rows])
    keys = store.keys()
    for key in keys:
        rec = store.take(key)
        acc.add(rec["corners"].astype(float), rec["index"], (grid, key))
    return acc.report(count, len(keys))


class MemoryBlocks:
    """``check_triangles``' blocks kept in memory (the records of all blocks at once)."""

    def __init__(self):
        self._parts: dict = {}

    def put(self, key: int, records: np.ndarray) -> None:
        self._parts.setdefault(key, []).append(np.array(records))

    def keys(self) -> list[int]:
        return sorted(self._parts)

    def take(self, key: int) -> np.ndarray:
        return np.concatenate(self._parts.pop(key))


class _BlockGrid:
    """Blocks of a uniform grid over the box [lo, hi], about ``count / block`` of them (cubes, at
    least one per axis); cell indices floor((x − lo) / size), clipped to the grid."""

    def __init__(self, lo, hi, count: int, block: int):
        ext = np.maximum(hi - lo, 0.0)
        n = max(2.0, 2.0 * count / block)  # a triangle may go to a few blocks: aim at half-full ones
        span = ext[ext > 0]
        size = float(np.prod(span) / n) ** (1.0 / len(span)) if len(span) else 1.0
        self.lo, self.size = lo, size
        self.dims = np.maximum(1, np.ceil(ext / size).astype(np.int64))

    def cells(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((x - self.lo) / self.size).astype(np.int64), 0, self.dims - 1)

    def key(self, c: np.ndarray) -> np.ndarray:
        return (c[..., 0] * self.dims[1] + c[..., 1]) * self.dims[2] + c[..., 2]

    def spread(self, b0: np.ndarray, b1: np.ndarray):
        """(block key, rows) for every block of the cell ranges [b0, b1] (k, 3) of the rows."""
        span = b1 - b0 + 1
        n = span.prod(axis=1)
        rows = np.repeat(np.arange(len(b0)), n)
        k = np.arange(len(rows)) - np.repeat(np.cumsum(n) - n, n)
        sy, sz = span[rows, 1], span[rows, 2]
        c = b0[rows] + np.stack([k // (sy * sz), (k // sz) % sy, k % sz], axis=1)
        keys = self.key(c)
        order = np.argsort(keys, kind="stable")
        keys, rows = keys[order], rows[order]
        starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
        for s, e in zip(starts, np.r_[starts[1:], len(keys)]):
            yield int(keys[s]), rows[s:e]


def weld(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (k, 3) of triangles (k, 3, 3): corners with equal coordinates
    are one vertex (−0 equal to 0), as consumers of STL merge them."""
    t = np.ascontiguousarray(triangles, float).reshape(-1, 3)
    if _compiled is not None:
        inv, first = (np.frombuffer(x, np.int64) for x in _compiled.weld(t))
        return t[first] + 0.0, inv.reshape(-1, 3)
    v, inv = np.unique(t + 0.0, axis=0, return_inverse=True)
    return v, inv.reshape(-1, 3)


def _lexicographic_less(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N,) bool: row p < row q in (x, y, z) order."""
    x, y = p[:, 0] == q[:, 0], p[:, 1] == q[:, 1]
    return (p[:, 0] < q[:, 0]) | (x & (p[:, 1] < q[:, 1])) | (x & y & (p[:, 2] < q[:, 2]))


class _Tally:
    """Counts of ``check_triangles`` summed over blocks."""

    def __init__(self):
        self.v = self.e = self.f = self.bad_edges = self.misoriented = self.degenerate = 0
        self.volume = 0.0
        self.pairs: list = []

    def add(self, tri: np.ndarray, index: np.ndarray, block) -> None:
        """One block: triangles (k, 3, 3), their indices in the soup, (grid, key) (None: all)."""
        if not len(tri):
            return
        v, f = weld(tri)

        def mine(points):
            return np.ones(len(points), bool) if block is None else block[0].key(block[0].cells(points)) == block[1]

        own_f = mine(tri.min(axis=1))
        self.f += int(own_f.sum())
        self.v += int(mine(v).sum())
        a, b, c = (tri[own_f, i] for i in range(3))
        self.volume += float(np.einsum("ij,ij->", a, cross(b, c))) / 6.0
        self.degenerate += int(degenerate(v, f)[own_f].sum())
        d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])  # directed edges
        p, q = v[d[:, 0]], v[d[:, 1]]
        forward = _lexicographic_less(p, q)  # runs from its smaller end (in coordinates, as in every block)
        keep = mine(np.where(forward[:, None], p, q))
        d, forward = d[keep], forward[keep]
        und = np.sort(d, axis=1)
        _, inv, n = np.unique(und[:, 0] * len(v) + und[:, 1], return_inverse=True, return_counts=True)
        fwd = np.bincount(inv.reshape(-1), forward, len(n))
        self.e += len(n)
        self.bad_edges += int((n != 2).sum())
        self.misoriented += int(((n == 2) & (fwd != 1)).sum())
        pairs = self_intersections(v, f)
        if block is not None and len(pairs):
            grid = block[0]
            corner = np.maximum(grid.cells(tri[pairs[:, 0]].min(axis=1)), grid.cells(tri[pairs[:, 1]].min(axis=1)))
            pairs = pairs[grid.key(corner) == block[1]]
        self.pairs.append(np.sort(index[pairs], axis=1))

    def report(self, count: int, blocks: int) -> dict:
        pairs = np.concatenate(self.pairs) if self.pairs else np.zeros((0, 2), np.int64)
        return {"triangles": int(count), "watertight": self.bad_edges == 0,
                "winding_consistent": self.bad_edges == 0 and self.misoriented == 0,
                "euler_characteristic": int(self.v - self.e + self.f), "volume": self.volume,
                "self_intersecting_pairs": int(len(pairs)), "self_intersecting_faces": int(len(np.unique(pairs))),
                "degenerate_faces": int(self.degenerate), "blocks": int(blocks)}
