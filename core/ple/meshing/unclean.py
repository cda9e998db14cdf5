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
