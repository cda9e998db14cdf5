"""Refined meshes without folds: every preset's `refined` mesh at levels 0–3 has no
self-intersecting faces, by the exact test (``ple.meshing.selfcheck``) and by an independent
one written here (an R-tree of face boxes and a separating-axis test in float64 on faces shrunk
towards their centroids, so that neighbours sharing a vertex or an edge no longer touch).

The folds came from the cones of point circles: a corridor ending in a point circle is a cone
whose apex has no arc parameter, and the mean of the apex's and a neighbour's coordinates left
the generator between them, so the planar triangle sharing that edge folded
(``ple.meshing.tessellate._param_mid``)."""

from __future__ import annotations

import numpy as np
import pytest
from ple.meshing.selfcheck import self_intersections
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

rtree = pytest.importorskip("rtree")

SHRINK = 1e-6  # faces shrunk by this fraction towards their centroids


def _axes(t1: np.ndarray, t2: np.ndarray, normals_only: bool = False) -> np.ndarray:
    """Candidate separating axes (k, 17, 3) of triangle pairs (k, 3, 3): both normals, the nine
    edge-edge cross products, and the in-plane edge normals (coplanar pairs); (k, 2, 3), the
    normals, with ``normals_only``."""
    e1 = np.roll(t1, -1, axis=1) - t1
    e2 = np.roll(t2, -1, axis=1) - t2
    n1 = np.cross(e1[:, 0], e1[:, 1])
    n2 = np.cross(e2[:, 0], e2[:, 1])
    if normals_only:
        return np.stack([n1, n2], axis=1)
    cross = np.cross(e1[:, :, None], e2[:, None, :]).reshape(-1, 9, 3)
    in1 = np.cross(n1[:, None], e1)
    in2 = np.cross(n2[:, None], e2)
    return np.concatenate([n1[:, None], n2[:, None], cross, in1, in2], axis=1)


def sat_intersecting_pairs(vertices, faces) -> np.ndarray:
    """Pairs (k, 2) of faces whose shrunk triangles overlap (no separating axis)."""
    v = np.asarray(vertices, float)
    tri = v[np.asarray(faces, np.int64)]
    cen = tri.mean(axis=1, keepdims=True)
    tri = cen + (1 - SHRINK) * (tri - cen)
    pairs = overlapping_boxes(tri.min(axis=1), tri.max(axis=1))
    out = []
    for chunk in np.array_split(pairs, max(1, len(pairs) // 200_000)):
        t1, t2 = tri[chunk[:, 0]], tri[chunk[:, 1]]
        # most pairs of neighbours are separated by a normal: the other 15 axes only for the rest
        chunk, t1, t2 = (x[~_separated(_axes(t1, t2, normals_only=True), t1, t2)] for x in (chunk, t1, t2))
        out.append(chunk[~_separated(_axes(t1, t2), t1, t2)])
    return np.concatenate(out) if out else np.zeros((0, 2), np.int64)


def _separated(ax: np.ndarray, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """bool (k,): is some axis of ``ax`` (k, a, 3) a separating axis of the triangles t1, t2 (k, 3, 3)?"""
    p1 = np.einsum("kad,kvd->kav", ax, t1)
    p2 = np.einsum("kad,kvd->kav", ax, t2)
    return ((p1.max(axis=2) < p2.min(axis=2)) | (p2.max(axis=2) < p1.min(axis=2))).any(axis=1)


def overlapping_boxes(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Pairs (k, 2), i < j, of the boxes lo..hi (n, 3) that overlap (closed). A box no wider than
    the grid step (twice the median width) is entered in the cells of a uniform grid that it meets
    (at most 8) and compared with those sharing a cell; each wider box (a few) asks an R-tree."""
    width = (hi - lo).max(axis=1)
    step = 2 * float(np.median(width)) or 1.0
    narrow = np.flatnonzero(width <= step)
    first = np.floor((lo[narrow] - lo.min(axis=0)) / step).astype(np.int64)
    span = np.floor((hi[narrow] - lo.min(axis=0)) / step).astype(np.int64) - first + 1  # 1 or 2 per axis
    dims = first.max(axis=0, initial=0) + 3
    entries = [(narrow[m], first[m] + d) for d in np.ndindex(2, 2, 2) for m in [np.all(np.array(d) < span, axis=1)]]
    box = np.concatenate([b for b, _ in entries])
    cell = np.concatenate([c for _, c in entries])
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    key, box = key[order], box[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    size = np.diff(np.r_[start, len(key)])
    later = np.repeat(start + size, size) - np.arange(len(key)) - 1  # the entries after each in its cell
    a = np.repeat(np.arange(len(key)), later)
    b = a + 1 + np.arange(len(a)) - np.repeat(np.cumsum(later) - later, later)
    pairs = [np.stack([box[a], box[b]], axis=1)]
    prop = rtree.index.Property()
    prop.dimension = 3
    idx = rtree.index.Index((np.arange(len(lo), dtype=np.int64), lo, hi), properties=prop)  # bulk loaded
    for i in np.flatnonzero(width > step):
        hits = np.fromiter(idx.intersection((*lo[i], *hi[i])), np.int64)
        pairs.append(np.stack([np.full(len(hits), i), hits], axis=1))
    pairs = np.sort(np.concatenate(pairs), axis=1)
    key = np.unique(pairs[:, 0] * len(lo) + pairs[:, 1])
    i, j = key // len(lo), key % len(lo)
    keep = (i < j) & np.all((lo[i] <= hi[j]) & (lo[j] <= hi[i]), axis=1)
    return np.stack([i[keep], j[keep]], axis=1)


def test_independent_check_finds_crossing_and_folded_faces():
    # two triangles crossing, a fold (two faces on one edge, coplanar, same side), a clean pair
    v = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, -1], [0.5, 0.5, 1], [1.5, 1.5, 0.0],
                  [1, 0.2, 0]], float)
    crossing = np.array([[0, 1, 2], [3, 4, 5]])
    assert len(sat_intersecting_pairs(v, crossing)) == 1
    folded = np.array([[0, 1, 2], [0, 1, 6]])  # vertex 6 lies inside face 0
    assert len(sat_intersecting_pairs(v, folded)) == 1
    hinge = np.array([[0, 1, 2], [1, 0, 3]])  # a shared edge, faces at an angle: clean
    assert len(sat_intersecting_pairs(v, hinge)) == 0


CASES = [
    ("octet", ["n=2", "radius=0.1"], None),  # thick: about 30 % relative density
    ("octet", [], "0:2,0:2,0:2"),
    ("becots_kagome", [], "0:4,0:4,0:1"),
    ("hier_lil2", [], "0:2,0:2,0:2"),
    ("thesis_warped", [], "0:2,0:2,0:2"),
    ("cubic", [], "0:2,0:2,0:2"),
    ("bcc", [], "0:2,0:2,0:2"),
    ("fig6_3", [], "0:2,0:2,0:2"),
]


@pytest.mark.parametrize("name,params,region", CASES, ids=[c[0] + ("_thick" if c[1] else "") for c in CASES])
@pytest.mark.parametrize("levels", [0, 1, 2, 3])
def test_refined_presets_have_no_self_intersections(name, params, region, levels):
    mesh = tessellate(load_lattice(name, params), region, "refined", levels)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert len(self_intersections(v, f)) == 0
    assert len(sat_intersecting_pairs(v, f)) == 0
