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

The unclean hubs U are left out of the fast mesh (whose beams towards them end in capped
contact disks, as at a region's border); the union of the fast mesh with U's balls and the
cone-beams (convex hulls of two balls) incident to U is one manifold3d boolean. Its result is a
closed, oriented 2-manifold whose volume is that of the union of balls and beams (up to the
polygonal balls, whose volume is matched to the exact ball's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.elements import segment_distance
from ..errors import PleError
from ..queries.overlaps import non_incident_pairs
from .selfcheck import self_intersections
from .weld import COLLAPSE_GRIDS, edge_manifold, snap, weld

TRIM = 0.5  # beams are tested from half their contact distance on (the rest is inside S⁺ of their hub)
SPHERE_SEGMENTS = 32


@dataclass
class UncleanReport:
    """Unclean hubs (rows of the evaluation's node arrays) and the overlaps found."""

    nodes: np.ndarray
    pairs: int
    shrunk_hubs: int
    components: int

    def line(self) -> str:
        return (f"unclean lattice: {len(self.nodes):,} hubs in {self.components:,} neighbourhoods "
                f"({self.pairs:,} overlapping element pairs, {self.shrunk_hubs:,} shrunk junctions) "
                f"united with manifold3d")


def find_unclean(center, radius, beam_nodes, r_plus, shrunk=None) -> UncleanReport:
    """Unclean hubs of a region from its balls (center (N, 3), radius (N,)), beams (M, 2 rows),
    each hub's inflated radius r_plus (N,) (world units) and ``shrunk`` (N,) hubs whose ACHoCC
    was not clean."""
    from scipy.sparse import coo_matrix  # noqa: PLC0415 - optional package
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    c = np.asarray(center, float).reshape(-1, 3)
    rad = np.asarray(radius, float).reshape(-1)
    rp = np.maximum(np.asarray(r_plus, float).reshape(-1), rad)
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    n, m = len(c), len(bn)
    bad = np.zeros(n, bool) if shrunk is None else np.asarray(shrunk, bool).copy()
    shrunk_count = int(bad.sum())
    # elements: hubs (point, radius r⁺) and beams (trimmed segment, radius max r)
    a, b = c[bn[:, 0]], c[bn[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    u = (b - a) / np.where(length > 0, length, 1)[:, None]
    ta = TRIM * np.sqrt(np.maximum(rp[bn[:, 0]] ** 2 - rad[bn[:, 0]] ** 2, 0))
    tb = TRIM * np.sqrt(np.maximum(rp[bn[:, 1]] ** 2 - rad[bn[:, 1]] ** 2, 0))
    seg0 = np.concatenate([c, a + u * ta[:, None]])
    seg1 = np.concatenate([c, b - u * tb[:, None]])
    rr = np.concatenate([rp, np.maximum(rad[bn[:, 0]], rad[bn[:, 1]])])
    ends = np.concatenate([np.repeat(np.arange(n)[:, None], 2, axis=1), bn])
    kinds = np.concatenate([np.zeros(n, np.int64), np.ones(m, np.int64)])
    lo = np.minimum(seg0, seg1) - rr[:, None]
    hi = np.maximum(seg0, seg1) + rr[:, None]
    pairs = 0
    # the one candidate search of non-incident elements (``queries.overlaps``), tested here with
    # the junctions' spheres S⁺: elements that share a ball, and hubs joined by a beam, are the
    # junctions' business
    for i, j in non_incident_pairs(ends, kinds, lo, hi, bn):
        hit = segment_distance(seg0[i], seg1[i], seg0[j], seg1[j]) < rr[i] + rr[j]
        pairs += int(hit.sum())
        bad[ends[i[hit]].reshape(-1)] = True
        bad[ends[j[hit]].reshape(-1)] = True
    nodes = np.flatnonzero(bad)
    comps = 0
    if len(nodes):
        sel = bad[bn[:, 0]] & bad[bn[:, 1]]
        g = coo_matrix((np.ones(int(sel.sum())), (bn[sel, 0], bn[sel, 1])), shape=(n, n))
        _, lab = connected_components(g, directed=False)
        comps = len(np.unique(lab[nodes]))
    return UncleanReport(nodes, pairs, shrunk_count, comps)


def _unit_sphere(manifold3d):
    """A polygonal unit sphere whose volume is the exact ball's (4π/3)."""
    s = manifold3d.Manifold.sphere(1.0, SPHERE_SEGMENTS)
    k = (4.0 / 3.0 * np.pi / s.volume()) ** (1.0 / 3.0)
    return s.scale([k, k, k])


def unite(mesh_vertices, mesh_faces, center, radius, beam_nodes, nodes, grid: float):
    """The manifold3d union of a closed mesh with the balls ``nodes`` and every beam incident
    to one of them (convex hull of its two balls), on the float32 grid ``grid`` (the region's
    ``ple.meshing.weld.grid_spacing``). Returns (vertices, faces).

    The Boolean runs on 64-bit input (``Mesh64``: float32 input moves vertices by up to half a
    float32 step, and the union keeps the folds that makes); its result is then put on the grid
    (``on_grid``), so the mesh in memory is the mesh every float32 file holds."""
    try:
        import manifold3d
    except ImportError as exc:  # pragma: no cover - a dev/runtime dependency
        raise PleError("meshing an unclean lattice needs manifold3d (pip install manifold3d)") from exc
    c = np.asarray(center, float)
    rad = np.asarray(radius, float)
    unit = _unit_sphere(manifold3d)
    ball = {}

    def ball_of(x):
        if x not in ball:
            ball[x] = unit.scale([rad[x]] * 3).translate(list(c[x]))
        return ball[x]

    parts = [ball_of(int(x)) for x in nodes]
    mark = np.zeros(len(c), bool)
    mark[nodes] = True
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    for x, y in bn[mark[bn[:, 0]] | mark[bn[:, 1]]]:
        # the cone-beam is the convex hull of its balls; built from the very ball meshes, so the
        # boolean meets coincident vertices (resolved symbolically), never near-tangent surfaces
        parts.append(manifold3d.Manifold.batch_hull([ball_of(int(x)), ball_of(int(y))]))
    local = manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add)
    # every point of the parts lies within ``reach`` of the centre of one of their balls
    involved = np.unique(np.concatenate([np.asarray(nodes, np.int64), bn[mark[bn[:, 0]] | mark[bn[:, 1]]].ravel()]))
    length = np.linalg.norm(c[bn[:, 0]] - c[bn[:, 1]], axis=1)[mark[bn[:, 0]] | mark[bn[:, 1]]]
    reach = float(np.max(rad[involved])) + (float(length.max()) / 2 if len(length) else 0.0)
    if len(mesh_faces):
        base = manifold3d.Manifold(manifold3d.Mesh64(
            vert_properties=np.ascontiguousarray(mesh_vertices, np.float64),
            tri_verts=np.ascontiguousarray(mesh_faces, np.uint64)))
        if base.status() != manifold3d.Error.NoError:
            raise PleError(f"the clean part of the mesh is not a manifold ({base.status()})")
        local = base + local
    out = local.to_mesh64()
    v, f = np.asarray(out.vert_properties[:, :3], float), np.asarray(out.tri_verts, np.int64)
    return on_grid(v, f, grid, c[involved], reach)


MAX_REPAIR_ROUNDS = 12


def on_grid(vertices, faces, grid: float, centers, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """A closed, self-intersection-free mesh moved onto the float32 grid ``grid`` so that it stays
    so: its edges under ``COLLAPSE_GRIDS`` grid steps are collapsed in 64 bits (link condition),
    the vertices snapped and welded (``ple.meshing.weld.weld``); then, on the faces with a corner within
    ``reach`` of one of ``centers`` (K, 3) (the united parts), while the
    exact check (``ple.meshing.selfcheck``) finds faces that meet when rounded once more, to twice
    the grid (slivers of the Boolean that a rounding tilts: a file in other units, glTF's metres,
    rounds the grid values again), the shortest edge of the thinner face of each pair is collapsed
    onto one of its grid vertices, and so is the shortest edge of every cap flatter than
    ``COLLAPSE_GRIDS`` grid steps. The exact check on the grid has the last word (PleError if it
    finds any pair). Returns (vertices on the grid, faces)."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    for _ in range(MAX_REPAIR_ROUNDS):
        e = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
        e = e[np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1) < COLLAPSE_GRIDS * grid]
        n = len(f)
        if not len(e) or len(f := collapse_edges(v, f, e, [])[0]) == n:
            break
    v, f, _ = weld(v, f, grid)
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    tree = cKDTree(np.asarray(centers, float).reshape(-1, 3))
    d, _ = tree.query(v, distance_upper_bound=reach + COLLAPSE_GRIDS * grid)
    near = np.flatnonzero(np.isfinite(d)[f].any(axis=1))
    for _ in range(MAX_REPAIR_ROUNDS):
        # a probe: the faces rounded once more, to twice the grid (a file in other units, glTF's
        # metres, rounds the grid values again): faces that fold there are too thin to keep
        probe = near[self_intersections(snap(v, 2 * grid), f[near])]
        # and caps flatter than the grid, which any rounding may fold onto their neighbours
        t = v[f[near]]
        e = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2)
        flat = near[np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
                    < COLLAPSE_GRIDS * grid * e.max(axis=1)]
        k = np.argmin(np.linalg.norm(v[f[flat][:, [1, 2, 0]]] - v[f[flat]], axis=2), axis=1)
        edges = np.concatenate([_thinner_edges(v, f, probe), np.stack([f[flat, k], f[flat, (k + 1) % 3]], axis=1)])
        n = len(f)
        if len(edges):
            f, near = collapse_edges(v, f, edges, near)
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
    return v[used], remap[f]


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


def collapse_edges(v, f, edges, near):
    """Collapse ``edges`` (E, 2) of a closed oriented mesh where the link condition holds, each
    onto the one of its two vertices that flips none of the moved faces; collapses of one call
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
