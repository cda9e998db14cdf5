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

from ..errors import PleError

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


def _seg_seg_distance(p0, p1, q0, q1) -> np.ndarray:
    """Distances between segments p0p1 and q0q1 (arrays (k, 3)), clamped closest points."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    den = a * e - b * b
    s = np.where(den > 1e-300, np.clip((b * f - c * e) / np.where(den > 1e-300, den, 1), 0, 1), 0.0)
    t = (b * s + f) / np.where(e > 1e-300, e, 1)
    t = np.clip(t, 0, 1)
    s = np.clip((b * t - c) / np.where(a > 1e-300, a, 1), 0, 1)
    return np.linalg.norm(p0 + d1 * s[:, None] - q0 - d2 * t[:, None], axis=1)


def find_unclean(center, radius, beam_nodes, r_plus, shrunk=None) -> UncleanReport:
    """Unclean hubs of a region from its balls (center (N, 3), radius (N,)), beams (M, 2 rows),
    each hub's inflated radius r_plus (N,) (world units) and ``shrunk`` (N,) hubs whose ACHoCC
    was not clean."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

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
    s0 = a + u * ta[:, None]
    s1 = b - u * tb[:, None]
    rb = np.maximum(rad[bn[:, 0]], rad[bn[:, 1]])
    ec = np.concatenate([c, 0.5 * (s0 + s1)])  # bounding spheres of every element
    er = np.concatenate([rp, 0.5 * np.linalg.norm(s1 - s0, axis=1) + rb])
    pairs = 0
    if n + m > 1:
        tree = cKDTree(ec)
        cand = tree.query_pairs(2 * float(er.max()), output_type="ndarray")
        cand = cand[np.linalg.norm(ec[cand[:, 0]] - ec[cand[:, 1]], axis=1) < er[cand[:, 0]] + er[cand[:, 1]]]
        i, j = cand[:, 0], cand[:, 1]
        ends = np.full((n + m, 2), -1, np.int64)
        ends[:n, 0] = np.arange(n)
        ends[n:] = bn
        # elements that share a ball are incident (their overlap is the junction's business)
        share = ((ends[i, :, None] == ends[j, None, :]) & (ends[i, :, None] >= 0)).any(axis=(1, 2))
        # two hubs joined by a beam are neighbours: their meeting is judged by the junctions
        adj = np.zeros(len(i), bool)
        hh = (i < n) & (j < n)
        if hh.any() and m:
            key = np.minimum(bn[:, 0], bn[:, 1]) * n + np.maximum(bn[:, 0], bn[:, 1])
            kk = np.minimum(i[hh], j[hh]) * n + np.maximum(i[hh], j[hh])
            adj[hh] = np.isin(kk, key)
        keep = ~share & ~adj
        i, j = i[keep], j[keep]
        seg0 = np.concatenate([c, s0])
        seg1 = np.concatenate([c, s1])
        rr = np.concatenate([rp, rb])
        d = _seg_seg_distance(seg0[i], seg1[i], seg0[j], seg1[j])
        hit = d < rr[i] + rr[j]
        pairs = int(hit.sum())
        for x in (i[hit], j[hit]):
            e = ends[x].reshape(-1)
            bad[e[e >= 0]] = True
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


def unite(mesh_vertices, mesh_faces, center, radius, beam_nodes, nodes):
    """The manifold3d union of a closed mesh with the balls ``nodes`` and every beam incident
    to one of them (convex hull of its two balls). Returns (vertices, faces)."""
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
    if len(mesh_faces):
        base = manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(mesh_vertices, np.float32),
                                                   tri_verts=np.asarray(mesh_faces, np.uint32)))
        if base.status() != manifold3d.Error.NoError:
            raise PleError(f"the clean part of the mesh is not a manifold ({base.status()})")
        local = base + local
    out = local.to_mesh()
    return np.asarray(out.vert_properties[:, :3], float), np.asarray(out.tri_verts, np.int64)
