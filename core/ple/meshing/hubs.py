"""Hub templates: the tessellated junction of one ball, alone or in batches (CHoCC paper 001_ §5–6).

``hub_template`` builds one hub: its ACHoCC junction (``ple.meshing.achocc``), the CNT or
sampled corridors of its CHoCC (``ple.meshing.chocc.corridor_mesh``), the §6 refinement and the
caps of its contact disks.

``hub_templates`` builds many hubs of one template node that have the same beams (a curved
steady lattice has one hub shape per (i, j) column). Neighbouring hubs differ only slightly,
so they share the combinatorics of their CHoCC: which circle triples make the triangles and
which pairs the corridors, how many strip quads each corridor has, which corridors degenerate
to an edge. One hub of a group (the representative) is built by ``hub_template``; every other
hub whose CHoCC has exactly that topology (validated per hub, as ``chocc.chocc`` validates a
hint) gets its vertices computed as arrays (hubs, …) — triangle vertices, corridor apexes and
arc samples, refinement and caps — and shares the representative's faces and rings. Unclean
junctions (r⁺ capped inside the beams, caps shrunk) are batched like clean ones, in batches of
one clean flag. Short edges are collapsed hub by hub on the patch around them, on snapped
positions in both paths (equal lengths then tie the same way). Hubs that differ (another
topology, an off-centre fix, the inflation loop, a coordinate on a snap boundary) are the next
representatives or are built alone.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from ..algebra.vectors import cross, perpendicular_frames, unit_rows
from ..errors import PleError
from .achocc import (
    CENTRE_MARGIN,
    INFLATE,
    UNCLEAN_GAP,
    HubGeometry,
    JunctionError,
    disk_reach,
    exit_distances,
    hub_geometry,
    pulled_circles,
)
from .chocc import (
    DEGENERATE_ARC,
    Chocc,
    ChoccMesh,
    apollonius_planes,
    circle_points,
    cnt_segments,
    cone_apex,
    contact_points,
    corridor_ends,
    corridor_mesh,
    generator_ends,
    sampled_segments,
    tie_broken,
)
from .fillet import filleted
from .selfcheck import self_intersections
from .weld import collapse_short_edges, follows_trace, ordered_short, sorted_edges

BATCH_VERTICES = 1 << 21  # vertices of one batch's largest array level (bounds the batch's memory)
REPS_KEPT = 8  # representatives a beam set keeps from one ``hub_templates`` call to the next
SNAP = 2.0**-24  # grid (hub units) of the positions whose lengths decide short-edge collapses
SNAP_GUARD = 1e-11  # round-off between the batch's and the per-hub path's vertices (hub units), with margin


@dataclass
class HubTemplate:
    """A hub mesh in the template frame: vertices (m, 3), outward faces (f, 3), per incident
    beam the ring of vertex ids on its contact circle (clockwise about the beam direction) and
    the fan faces capping its disk (using one extra vertex, the disk centre). ``row``: where a
    template table (``ple.meshing.assembly``) holds its arrays, once it does."""

    vertices: np.ndarray
    faces: np.ndarray
    rings: list
    caps: list
    geometry: HubGeometry
    row: tuple | None = None


def _segments(style: str, segments: int):
    return cnt_segments if style in ("cnt", "refined") else sampled_segments(segments)


def refine_arrays(verts, hull, faces, fcor, fpar, rings, real, normals, alphas, rho, corridor_point,
                  exit_distance, levels: int, corridors=None):
    """§6 refinement of H hubs with one CNT topology: ``levels`` 1-to-4 splits (a corridor quad,
    two triangles, becomes 8 around its centre), arc midpoints snapped to their circle, other new
    vertices centrally projected.

    verts (H, V, 3) in hub units (centre at 0), hull (H, V, 3) the same vertices on the CHoCC
    hull (unit sphere); faces (F, 3), their corridor fcor (F,) (-1: a planar CHoCC triangle) and
    corridor coordinates fpar (F, 3, 2); rings (per circle, vertex ids) of which the first
    ``real`` are contact circles; normals (H, n, 3), alphas (H, n), rho (H, real) the distance of
    each contact circle from the centre (r⁺, or nearer where a short beam pulls it in);
    ``corridor_point(cor (k,), s (k,), t (k,))`` -> (H, k, 3) points of the curved corridors;
    ``exit_distance(u (H, k, 3))`` -> (H, k) distance to the lattice along unit rays.

    A new vertex is first placed on the CHoCC hull itself — on a planar triangle, or on the
    curved corridor at the mean of its corners' corridor coordinates — and then projected from
    the centre. A point of the planar CNT quad near a long arc's chord lies in that circle's
    cone, and its projection would land on the beam beyond the contact disk, folding into the
    beam's strip; a point of the hull never does (the centre is inside the hull, so the cones
    over its faces, corridors and disks do not overlap). ``corridors`` (k, ≥2): the circles each
    corridor joins, to find the corridors that are cones (one end a point circle, alpha 0), whose
    apex edges are generators. Returns (verts (H, V', 3), faces, rings)."""
    e1, e2 = perpendicular_frames(normals)
    # per corridor: is its end a (t = 0) / b (t = 1) a point circle (the corridor is a cone with its apex there)
    ends = np.asarray(corridors)[:, :2] if corridors is not None and len(corridors) else np.zeros((0, 2), np.int64)
    point_end = np.concatenate([np.asarray(alphas)[0][ends] == 0.0, np.zeros((1, 2), bool)])  # row -1: triangles
    rho = np.asarray(rho, float)
    rings = [np.asarray(r).copy() for r in rings]
    for _ in range(levels):
        nv = verts.shape[1]
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        ekey = np.minimum(e[:, 0], e[:, 1]) * nv + np.maximum(e[:, 0], e[:, 1])
        uniq, inv = np.unique(ekey, return_inverse=True)
        inv = inv.reshape(-1)
        ua, ub = uniq // nv, uniq % nv
        ecor = np.tile(fcor, 3)
        apex = _apex_corners(fcor, fpar, point_end)
        p01, p12, p20 = (_param_mid(fpar[:, i], fpar[:, j], apex[:, i], apex[:, j])
                         for i, j in ((0, 1), (1, 2), (2, 0)))
        epar = np.concatenate([p01, p12, p20])
        # one hull point per edge: a corridor's if any face on it is a corridor (they agree on
        # the generators shared with triangles), else the chord's midpoint on a triangle
        pick = np.full(len(uniq), -1)
        order = np.argsort(ecor >= 0, kind="stable")  # triangles first, corridors overwrite
        pick[inv[order]] = order
        hnew = 0.5 * (hull[:, e[pick, 0]] + hull[:, e[pick, 1]])
        onc = np.flatnonzero(ecor[pick] >= 0)
        if len(onc):
            p = pick[onc]
            hnew[:, onc] = corridor_point(ecor[p], epar[p, 0], epar[p, 1])
        mids = 0.5 * (verts[:, ua] + verts[:, ub])
        new_ids = nv + np.arange(len(uniq))
        is_arc = np.zeros(len(uniq), bool)
        arcs = []
        for ci in range(real):
            ring = rings[ci]
            if len(ring) < 2:
                continue
            x, y = ring, np.roll(ring, -1)
            q = np.searchsorted(uniq, np.minimum(x, y) * nv + np.maximum(x, y))
            arcs.append((q, x, y, np.full(len(q), ci)))
            out = np.empty(2 * len(ring), np.int64)
            out[0::2], out[1::2] = ring, new_ids[q]
            rings[ci] = out
        if arcs:
            q, x, y, ci = (np.concatenate(a) for a in zip(*arcs))
            is_arc[q] = True
            rp = rho[:, ci][..., None]
            mids[:, q] = _arc_mids(verts[:, x], verts[:, y], normals[:, ci], alphas[:, ci], rp, e1[:, ci], e2[:, ci])
            hnew[:, q] = mids[:, q] / rp
        proj = ~is_arc
        if proj.any():
            u = hnew[:, proj] / np.linalg.norm(hnew[:, proj], axis=-1, keepdims=True)
            mids[:, proj] = u * exit_distance(u)[..., None]
        verts = np.concatenate([verts, mids], axis=1)
        hull = np.concatenate([hull, hnew], axis=1)
        m = new_ids[inv].reshape(3, -1).T  # midpoints of edges 01, 12, 20 per face
        v0, v1, v2 = faces.T
        faces = np.concatenate([np.stack([v0, m[:, 0], m[:, 2]], 1), np.stack([m[:, 0], v1, m[:, 1]], 1),
                                np.stack([m[:, 2], m[:, 1], v2], 1), m])
        p0, p1, p2 = fpar[:, 0], fpar[:, 1], fpar[:, 2]
        fpar = np.concatenate([np.stack([p0, p01, p20], 1), np.stack([p01, p1, p12], 1),
                               np.stack([p20, p12, p2], 1), np.stack([p01, p12, p20], 1)])
        fcor = np.tile(fcor, 4)
    return verts, faces, rings


def _apex_corners(fcor: np.ndarray, fpar: np.ndarray, point_end: np.ndarray) -> np.ndarray:
    """Which corners (f, 3) of the faces are the apex of their corridor's cone: the single vertex
    of a point circle, whose arc parameter s is arbitrary (every generator ends there)."""
    t = fpar[..., 1]
    return ((t == 0.0) & point_end[fcor, 0][:, None]) | ((t == 1.0) & point_end[fcor, 1][:, None])


def _param_mid(pa: np.ndarray, pb: np.ndarray, apex_a: np.ndarray, apex_b: np.ndarray) -> np.ndarray:
    """Corridor coordinates (k, 2) of the midpoints of edges with end coordinates pa, pb (k, 2).
    An edge from a cone's apex is a generator: its midpoint keeps the other end's s (the mean
    would leave the edge, and the planar triangle sharing it would fold)."""
    mid = 0.5 * (pa + pb)
    mid[:, 0] = np.where(apex_a & ~apex_b, pb[:, 0], np.where(apex_b & ~apex_a, pa[:, 0], mid[:, 0]))
    return mid


def _arc_mids(pa, pb, n, alpha, r_plus, e1, e2) -> np.ndarray:
    """Midpoints of the clockwise arcs (about n) from pa (..., 3) to pb on circles (n (..., 3),
    alpha (...)) of S⁺ with frames e1, e2 (..., 3)."""
    dot = lambda p, f: np.einsum("...i,...i->...", p, f)  # noqa: E731
    ta, tb = np.arctan2(dot(pa, e2), dot(pa, e1)), np.arctan2(dot(pb, e2), dot(pb, e1))
    d = (ta - tb) % (2 * np.pi)
    d[d > 2 * np.pi - 1e-9] = 0.0
    t = ta - d / 2
    ring = np.cos(t)[..., None] * e1 + np.sin(t)[..., None] * e2
    return r_plus * (np.cos(alpha)[..., None] * n + np.sin(alpha)[..., None] * ring)


def _refine(mesh: ChoccMesh, hub: HubGeometry, levels: int) -> tuple[np.ndarray, np.ndarray, list]:
    """``refine_arrays`` of one hub's CNT; its point circles (off-centre fix, seeds) are
    projected onto the lattice first. Returns vertices in hub units, faces, rings."""
    c = hub.chocc
    verts = _on_circles(mesh, hub)
    off = mesh.vertex_circle >= hub.slots
    if off.any():  # point circles: onto the lattice too
        u = verts[off] / np.linalg.norm(verts[off], axis=1, keepdims=True)
        verts[off] = u * hub.exit_distance(u)[:, None]
    faces = mesh.faces
    fcor = mesh.face_corridor if mesh.face_corridor is not None else np.full(len(faces), -1)
    fpar = mesh.face_params if mesh.face_params is not None else np.zeros((len(faces), 3, 2))
    v, f, rings = refine_arrays(verts[None], mesh.vertices[None], faces, fcor, fpar, mesh.rings, hub.slots,
                                c.normals[None], c.alphas[None], hub.circle_radii()[None],
                                lambda cor, s, t: mesh.corridor_point(cor, s, t)[None],
                                lambda u: hub.exit_distance(u[0])[None], levels, c.corridors)
    return v[0], f, rings


def _on_circles(mesh: ChoccMesh, hub: HubGeometry) -> np.ndarray:
    """The CNT's unit-sphere vertices at their circles' distances (hub units): r⁺, or each
    contact circle's own ``rho`` (``achocc.pulled_circles``); point circles stay at r⁺."""
    if hub.rho is None:
        return mesh.vertices * hub.r_plus
    radii = np.concatenate([hub.rho, np.full(max(hub.chocc.n - hub.slots, 0), hub.r_plus)])
    return mesh.vertices * radii[mesh.vertex_circle][:, None]


def _caps(rings: list, nv: int) -> list:
    """Fan faces capping each contact disk (one extra vertex per disk, ids nv, nv + 1, …):
    counter-clockwise about the beam, the disk's outward orientation."""
    caps = []
    for s, ring in enumerate(rings):
        q = ring[::-1]
        caps.append(np.stack([np.full(len(q), nv + s), q, np.roll(q, -1)], axis=1))
    return caps


def _hub_surface(hub, style: str, levels: int, segments: int):
    """The hub's surface without its caps: (vertices in hub units, faces, rings, CNT or CHoCC mesh)."""
    base = corridor_mesh(hub.chocc, _segments(style, segments))
    if style == "refined":
        verts, faces, rings = _refine(base, hub, levels)
    else:
        verts, faces, rings = _on_circles(base, hub), base.faces, base.rings
    return verts, faces, rings, base


def hub_template(center, radius, neighbor_centers, neighbor_radii, style: str, levels: int,
                 segments: int, hint=None, min_edge: float = 0.0, fillet: float | None = None,
                 _surface: list | None = None, target=None) -> HubTemplate:
    """Tessellate one junction: ball (center (3,), radius) with beams to the balls
    (neighbor_centers (S, 3), neighbor_radii (S,)), in the given style. Edges shorter than
    ``min_edge`` are collapsed (``ple.meshing.weld.collapse_short_edges``) so that the mesh keeps its
    topology when written in float32. (``_surface``: a list that receives the surface before
    collapses and the CNT mesh, for ``hub_templates``.) ``target``: an optional wrapper of the
    HubGeometry whose ``exit_distance`` the refined vertices are projected to (default: the
    lattice, or the fillet)."""
    center = np.asarray(center, float)
    vec = np.asarray(neighbor_centers, float).reshape(-1, 3) - center
    lengths = np.linalg.norm(vec, axis=1)
    if np.any(lengths <= 0):
        raise JunctionError("a beam has length 0 (its two balls share a centre)", np.flatnonzero(lengths <= 0)[:1])
    dirs = vec / lengths[:, None]
    hub = hub_geometry(radius, dirs, np.asarray(neighbor_radii, float).reshape(-1), lengths, hint)
    hub = filleted(hub, fillet, hint)  # optional junction fillet (001_ §6 Eq. 6): projection onto the blend
    hub = target(hub) if target is not None else hub
    verts, faces, rings, base = _hub_surface(hub, style, levels, segments)
    if _surface is not None:
        _surface += [faces, rings, base]
    if min_edge > 0:  # lengths of snapped positions: the batch (``_collapsed``) sees the same ones
        faces, rings, _ = collapse_short_edges(_snapped(verts), faces, rings, min_edge)
    axial = hub.disk_axial()
    rings = [rings[s] for s in range(hub.slots)]
    disk_centres = dirs * axial[:, None]
    caps = _caps(rings, len(verts))
    if folded(np.concatenate([verts, disk_centres]), faces, caps, hub.pulled):
        hub.clean = False  # folded: left to a local union (``ple.meshing.unions``)
    return HubTemplate(np.concatenate([verts, disk_centres]) + center, faces, rings, caps, hub)


def star_shaped(verts: np.ndarray, faces: np.ndarray, caps: list) -> bool:
    """Whether a closed hub mesh (vertices (V, 3) relative to its centre, faces and cap fans)
    has every face turned outward as seen from the centre: its faces' cones then cover each
    direction once (the mesh encloses the centre: degree one), so no two faces meet. A junction
    of pulled-in circles (``achocc.pulled_circles``) is kept only if it passes."""
    f = np.concatenate([np.asarray(faces).reshape(-1, 3), *[np.asarray(c).reshape(-1, 3) for c in caps]])
    t = verts[f]
    return bool(np.all(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])) > 0))


def folded(verts: np.ndarray, faces: np.ndarray, caps: list, pulled: bool) -> bool:
    """Whether a closed hub mesh (vertices relative to its centre, faces, cap fans) may meet
    itself, so that its junction is left to a local union. A star-shaped mesh (``star_shaped``)
    is embedded. A junction of pulled circles must be star-shaped; any other is tested exactly
    (``selfcheck.self_intersections``) when it is not: a refined hub whose beams leave it at
    very different angles (a filter that removes some of them) can fold where its projection
    onto the balls and cones turns back."""
    if star_shaped(verts, faces, caps):
        return False
    if pulled:
        return True
    f = np.concatenate([np.asarray(faces).reshape(-1, 3), *[np.asarray(c).reshape(-1, 3) for c in caps]])
    return len(self_intersections(verts, f, workers=1)) > 0


# ----- batches ----------------------------------------------------------------------------
@dataclass
class _Geometries:
    """The ACHoCC junctions of H hubs with S ≥ 3 beams (``achocc.hub_geometry`` as arrays):
    ok (H,) where the batch can tell the junction (no inflation loop, every contact circle a
    real circle under a hemisphere), r_plus (H,), alphas (H, S), clean (H,), and rho (H, S) the
    contact circles' distances (r⁺ but where a short beam pulls its circle in), pulled (H,)."""

    ok: np.ndarray
    r_plus: np.ndarray
    alphas: np.ndarray
    clean: np.ndarray
    rho: np.ndarray
    pulled: np.ndarray


def _geometries(radius, dirs, other, lengths) -> _Geometries:
    """r⁺ (§5) and contact circles of H hubs at once, clean or not (``hub_geometry``: an unclean
    hub's r⁺ is capped at ``_max_inflation``'s limit and its overlapping caps shrunk to their
    share); hubs that ``hub_geometry`` would treat otherwise (clean caps touching at r⁺: the
    inflation loop; a contact circle shrunk to a point) are marked not ok and are built alone."""
    r = radius[:, None]
    sphi = (r - other) / lengths
    ok = np.all(np.abs(sphi) < 1, axis=1)
    sphi = np.where(ok[:, None], sphi, 0.0)
    cphi = np.sqrt(1 - sphi * sphi)
    i, j = np.triu_indices(dirs.shape[1], 1)
    cos_t = np.clip(np.einsum("hmi,hmi->hm", dirs[:, i], dirs[:, j]), -1, 1)
    sin_t = np.sqrt(1 - cos_t**2)
    ok &= ~np.any((sin_t < 1e-9) & (cos_t > 0), axis=1)
    # inflated_radius: profiles of beams i and j in the plane of their axes (§5)
    n1x, n1y = sphi[:, i], cphi[:, i]
    n2x = sphi[:, j] * cos_t + cphi[:, j] * sin_t
    n2y = sphi[:, j] * sin_t - cphi[:, j] * cos_t
    det = n1x * n2y - n1y * n2x
    safe = np.abs(det) > 1e-12
    det = np.where(safe, det, 1.0)
    px = r * (n2y - n1y) / det
    py = r * (n1x - n2x) / det
    forward = safe & (px > 0) & (px * cos_t + py * sin_t > 0)
    cand = np.where(forward, np.hypot(px, py), r)
    r_plus = np.maximum(radius, cand.max(axis=1)) * (1 + INFLATE)
    r_plus = np.maximum(r_plus, radius / cphi.min(axis=1) * (1 + 1e-2))
    # _max_inflation: beyond it the junction is unclean and r⁺ stays inside the beams, unless the
    # short beams' circles can be pulled in (``achocc.pulled_circles``)
    reach = disk_reach(r, sphi, cphi, other, lengths)
    limit = np.sqrt(radius**2 + reach.min(axis=1) ** 2)
    n = dirs.shape[1]
    theta = np.arccos(np.clip(np.einsum("hai,hbi->hab", dirs, dirs), -1, 1))
    theta[:, np.arange(n), np.arange(n)] = np.inf
    p_alphas, p_rho, p_ok = pulled_circles(r, r_plus[:, None], sphi, cphi, reach, theta)
    pulled = (r_plus > limit) & p_ok
    clean = (r_plus <= limit) | pulled
    r_plus = np.where(clean, r_plus, np.maximum(limit, radius))
    # contact_circles (strict only for clean hubs)
    s = np.sqrt(np.maximum(r_plus**2 - radius**2, 0.0))[:, None]
    x = r * sphi + s * cphi
    y = r * cphi - s * sphi
    ok &= ~clean | pulled | np.all((y > 0) & (x < lengths), axis=1)
    alphas = np.where(pulled[:, None], p_alphas, np.arctan2(np.maximum(y, 0.0), x))
    gap = theta - (alphas[:, :, None] + alphas[:, None, :])
    touching = (gap.min(axis=(1, 2)) <= 1e-9) & ~pulled
    ok &= ~(clean & touching)  # the inflation loop of hub_geometry: built alone
    # unclean caps overlapping at the allowed r⁺: each shrunk to its share (hub_geometry)
    share = (theta - UNCLEAN_GAP) * alphas[:, :, None] / np.maximum(alphas[:, :, None] + alphas[:, None, :], 1e-300)
    share[:, np.arange(n), np.arange(n)] = np.inf
    shrunk = np.clip(np.minimum(alphas, share.min(axis=2)), 0.0, None)
    alphas = np.where(touching[:, None], shrunk, alphas)
    ok &= np.all((alphas > 0) & (alphas < np.pi / 2), axis=1)
    rho = np.where(pulled[:, None], p_rho, r_plus[:, None])
    return _Geometries(ok, r_plus, alphas, clean, rho, pulled)


def _strict_hull(normals, alphas, tris):
    """Which hubs have exactly the triangles ``tris`` as their CHoCC (``chocc._topology_from_hint``
    per hub): every triangle's plane strictly supports all other circles with the rolling
    orientation. normals (H, n, 3), alphas (H, n). Returns ok (H,) and the candidates
    (normals (H, t, 2, 3), angles (H, t, 2), contacts (H, t, 2, 3, 3), ccw (H, t, 2))."""
    pn, pa = apollonius_planes(normals[:, tris], alphas[:, tris])
    pts = contact_points(pn[..., None, :], pa[..., None], normals[:, tris][:, :, None])
    ccw = np.einsum("...i,...i->...", cross(pts[..., 1, :] - pts[..., 0, :], pts[..., 2, :] - pts[..., 0, :]), pn)
    lim = np.minimum(pa[..., None] + alphas[:, None, None, :], np.pi)
    viol = np.einsum("htsi,hmi->htsm", pn, normals) - np.cos(lim)
    own = np.zeros((len(tris), normals.shape[1]), bool)
    own[np.arange(len(tris))[:, None], tris] = True
    viol = np.where(own[None, :, None, :], -np.inf, viol)
    good = (ccw > 1e-12) & (viol.max(axis=-1) <= -1e-9)  # strict: ties go to plane rolling
    return np.all(good.sum(axis=-1) == 1, axis=1), (pn, pa, pts, ccw)


class _Batch:
    """Hubs (H of them) in the representative's topology: CHoCC, CNT and corridors as arrays."""

    def __init__(self, rep: HubGeometry, normals, alphas, r_plus, rho, style: str, segments: int):
        c = rep.chocc
        self.tris, self.cors = c.triangles, c.corridors
        ok, (pn, pa, pts, ccw) = _strict_hull(normals, alphas, self.tris)
        if not ok.all():  # hubs with ties: the topology plane rolling finds for them
            redo = np.flatnonzero(~ok)
            ok[redo] = _strict_hull(normals[redo], tie_broken(normals[redo], alphas[redo]), self.tris)[0]
        # of the two candidates, the supporting one with the rolling orientation (``chocc.chocc``)
        lim = np.minimum(pa[..., None] + alphas[:, None, None, :], np.pi)
        viol = (np.einsum("htsi,hmi->htsm", pn, normals) - np.cos(lim)).max(axis=-1)
        key = np.where(viol <= 1e-8, 1.0, 0.0) * 10 + np.sign(np.round(ccw, 14))
        pick = np.argmax(key, axis=-1)[..., None]
        self.plane_normals = np.take_along_axis(pn, pick[..., None], axis=2)[:, :, 0]
        self.plane_alphas = np.take_along_axis(pa, pick, axis=2)[:, :, 0]
        self.points = np.take_along_axis(pts, pick[..., None, None], axis=2)[:, :, 0]
        self.normals, self.alphas, self.r_plus, self.rho = normals, alphas, r_plus, rho
        self.frames = perpendicular_frames(normals)
        a, b, t1, t2 = self.cors.T
        corner = lambda t, x: np.argmax(self.tris[t] == x[:, None], axis=1)  # noqa: E731
        self.ends = (self.points[:, t1, corner(t1, a)], self.points[:, t2, corner(t2, a)],
                     self.points[:, t2, corner(t2, b)], self.points[:, t1, corner(t1, b)])  # a0, a1, b1, b0
        pa0, pa1, pb1, pb0 = self.ends
        self.th_a0, self.th_b0 = self._angle(a, pa0), self._angle(b, pb0)
        na, nb, aa, ab = normals[:, a], normals[:, b], alphas[:, a], alphas[:, b]
        self.apexes = (cone_apex(na, nb, aa, ab), cone_apex(nb, na, ab, aa))  # (H, C, 4) each
        self.da = self._cw(self.th_a0, self._angle(a, pa1))  # clockwise on a from T1 to T2
        self.db = self._cw(self._angle(b, pb1), self.th_b0)  # clockwise on b from T2 to T1
        degenerate = ((np.maximum(self.da, self.db) < DEGENERATE_ARC)
                      & (np.linalg.norm(pa1 - pa0, axis=-1) < DEGENERATE_ARC)
                      & (np.linalg.norm(pb1 - pb0, axis=-1) < DEGENERATE_ARC))
        self.m = np.where(degenerate, 0, _segments(style, segments)(np.maximum(self.da, self.db)))
        # the same CNT as the representative's: strip quads per corridor, bare-edge corridors
        ok &= np.all(self.m == self.m[:1], axis=1) & (self.centre_depth() > CENTRE_MARGIN)
        self.ok = ok

    def _angle(self, i, p):
        e1, e2 = self.frames[0][:, i], self.frames[1][:, i]
        return np.arctan2(np.einsum("hci,hci->hc", p, e2), np.einsum("hci,hci->hc", p, e1))

    @staticmethod
    def _cw(th0, th1):
        d = (th0 - th1) % (2 * np.pi)
        return np.where(d > 2 * np.pi - 1e-9, 0.0, d)

    def centre_depth(self) -> np.ndarray:
        """``achocc._visible_face`` per hub: the smallest depth of the centre below the CNT's
        face planes (triangles and planar corridor quads); the off-centre fix adds point
        circles when it is at most CENTRE_MARGIN (those hubs are built alone)."""
        h = np.round(np.cos(self.plane_alphas), 9).min(axis=1)
        qa0, qa1, qb1, qb0 = self.ends
        nrm = cross(qa1 - qb0, qb1 - qa0)
        ln = np.linalg.norm(nrm, axis=-1)
        good = ln > 1e-12
        hq = np.where(good, np.round(np.einsum("hci,hci->hc", nrm, qa0) / np.where(good, ln, 1.0), 9), np.inf)
        return np.minimum(h, hq.min(axis=1)) if hq.shape[1] else h

    def take(self, keep: np.ndarray) -> None:
        """Keep the hubs ``keep`` (indices or mask) only."""
        for name in ("plane_normals", "plane_alphas", "points", "normals", "alphas", "r_plus", "rho", "th_a0", "th_b0",
                     "da", "db", "m", "ok"):
            setattr(self, name, getattr(self, name)[keep])
        self.frames = (self.frames[0][keep], self.frames[1][keep])
        self.apexes = (self.apexes[0][keep], self.apexes[1][keep])
        self.ends = tuple(e[keep] for e in self.ends)

    def corridor_ends(self, cor: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both ends (H, k, 3) of the generators at arc parameters s (k,) of corridors cor (k,):
        ``chocc.corridor_ends``, which samples the larger circle of each and maps the samples to
        the other through the cone's apex. Where every hub of the batch has the same larger
        circle on a corridor (the usual case), only that side is computed (the same operations,
        so the same values)."""
        a, b = self.cors[cor, 0], self.cors[cor, 1]
        e1, e2 = self.frames
        na, nb, aa, ab = self.normals[:, a], self.normals[:, b], self.alphas[:, a], self.alphas[:, b]
        big = aa >= ab
        on_a, on_b = big.all(axis=0), ~big.any(axis=0)
        if not (on_a | on_b).all():  # a corridor whose larger circle differs between hubs: both sides
            return corridor_ends(na, nb, aa, ab, (e1[:, a], e2[:, a]), (e1[:, b], e2[:, b]), self.th_a0[:, cor],
                                 self.da[:, cor], self.th_b0[:, cor], self.db[:, cor], s[None],
                                 (self.apexes[0][:, cor], self.apexes[1][:, cor]))
        pa, pb = np.empty(na.shape), np.empty(nb.shape)
        for side, cols in ((0, np.flatnonzero(on_a)), (1, np.flatnonzero(on_b))):
            if not len(cols):
                continue
            c, sc = cor[cols], s[cols][None]
            if side == 0:  # sweep a, map to b (as ``chocc.corridor_ends`` where a is the larger)
                p = circle_points(na[:, cols], aa[:, cols], e1[:, a[cols]], e2[:, a[cols]],
                                  self.th_a0[:, c] - sc * self.da[:, c])
                pa[:, cols], pb[:, cols] = p, generator_ends(p, self.apexes[0][:, c], nb[:, cols], ab[:, cols])
            else:
                p = circle_points(nb[:, cols], ab[:, cols], e1[:, b[cols]], e2[:, b[cols]],
                                  self.th_b0[:, c] + sc * self.db[:, c])
                pa[:, cols], pb[:, cols] = generator_ends(p, self.apexes[1][:, c], na[:, cols], aa[:, cols]), p
        return pa, pb

    def corridor_point(self, cor, s, t) -> np.ndarray:
        pa, pb = self.corridor_ends(cor, s)
        return (1 - t)[None, :, None] * pa + t[None, :, None] * pb

    def cnt_vertices(self) -> np.ndarray:
        """Vertices (H, V, 3) of the CNT/CHoCC mesh on the unit sphere in ``corridor_mesh``'s order:
        the triangles' corners, then per corridor its inner samples on a, then on b."""
        m = self.m[0]
        cor = np.repeat(np.arange(len(m)), np.maximum(m - 1, 0))
        step = np.concatenate([np.arange(1, k) for k in m]) if len(cor) else np.zeros(0)
        pa, pb = self.corridor_ends(cor, step / np.maximum(m[cor], 1))
        parts = [self.points.reshape(len(self.points), -1, 3)]
        bounds = np.concatenate([[0], np.cumsum(np.maximum(m - 1, 0))])
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            if hi > lo:
                parts += [pa[:, lo:hi], pb[:, lo:hi]]
        return np.concatenate(parts, axis=1)


def hub_templates(centers, radii, neighbor_centers, neighbor_radii, style: str, levels: int, segments: int,
                  hint=None, min_edge: float = 0.0, fillet: float | None = None,
                  batched: bool = True, reps: list | None = None) -> tuple[list, object]:
    """Templates of H hubs with S beams each: balls (centers (H, 3), radii (H,)) with beams to
    the balls (neighbor_centers (H, S, 3), neighbor_radii (H, S)).
    Equal to ``hub_template`` hub by hub (up to round-off), computed in batches of one CHoCC
    topology (``batched``; False: one by one, the reference path). ``hint``: base triangles of a
    similar hub. ``reps``: representatives of earlier calls with these beams (``Rep``), tried
    first as the batches' topologies (each hub is validated against one as against a new one);
    the list is replaced by this call's, the most recent first (at most REPS_KEPT). Returns
    (templates, the last hint)."""
    radii = np.asarray(radii, float).reshape(-1)
    centers = np.asarray(centers, float).reshape(len(radii), 3)
    nbc = np.asarray(neighbor_centers, float).reshape(len(radii), -1, 3)
    nbr = np.asarray(neighbor_radii, float).reshape(len(radii), -1)
    h_count, s_count = nbc.shape[:2]
    known = [r for r in (reps or []) if r.neighbor_centers.shape == (s_count, 3)] if batched and not fillet else []
    if known:  # the earlier representatives as rows after the hubs: each leads a batch as a new one would
        centers = np.concatenate([centers, [r.center for r in known]])
        radii = np.concatenate([radii, [r.radius for r in known]])
        nbc = np.concatenate([nbc, [r.neighbor_centers for r in known]])
        nbr = np.concatenate([nbr, [r.neighbor_radii for r in known]])
    out: list = [None] * len(radii)
    vec = nbc - centers[:, None]
    lengths = np.linalg.norm(vec, axis=-1)
    alone = np.ones(len(radii), bool)
    if batched and s_count >= 3 and not fillet:
        ok = np.all(lengths > 0, axis=1)
        dirs = vec / np.where(ok[:, None], lengths, 1.0)[..., None]
        geo = _geometries(radii, dirs, nbr, np.where(ok[:, None], lengths, 1.0))
        alone = ~(ok & geo.ok)
    todo = np.arange(len(radii)) < h_count
    used: list = []
    for k, rep in enumerate(known):  # earlier topologies first: no per-hub build for them
        rest = np.flatnonzero(todo & ~alone & (geo.clean == rep.geometry.clean))
        if len(rest) and not alone[h_count + k]:
            _batch_round(out, h_count + k, rep.geometry, rep.surface, rest, todo, centers, radii, nbc, dirs, nbr,
                         lengths, geo, style, levels, segments, min_edge, hint)
            if any(out[g] is not None for g in rest):
                used.append(rep)
    made: list = []
    for h in range(h_count):
        if not todo[h]:
            continue
        surface: list = []
        out[h] = _named(h, hub_template, centers[h], radii[h], nbc[h], nbr[h], style, levels, segments, hint,
                        min_edge, fillet, surface)
        todo[h] = False
        hub = out[h].geometry
        hint = hub.base_triangles
        if alone[h] or hub.chocc.n != s_count:
            continue  # no batch: this hub is special (point circles of the off-centre fix)
        made.append(Rep(centers[h], radii[h], nbc[h], nbr[h], surface, hub))
        rest = np.flatnonzero(todo & ~alone & (geo.clean == hub.clean))
        if len(rest):
            _batch_round(out, h, hub, surface, rest, todo, centers, radii, nbc, dirs, nbr, lengths, geo, style,
                         levels, segments, min_edge, hint)
    if reps is not None:
        reps[:] = (made[::-1] + used)[:REPS_KEPT]
    return out[:h_count], hint


def _named(h: int, build, *args):
    """``build(*args)`` for the hub of row h; a junction it cannot build raises ``JunctionError``
    naming that row (the CHoCC's own errors and a numerical failure of its hull included)."""
    try:
        return build(*args)
    except JunctionError as e:
        raise JunctionError(e.reason, e.beams, h) from None
    except (PleError, np.linalg.LinAlgError) as e:
        raise JunctionError(f"no convex hull of its contact circles ({e})", (), h) from None


@dataclass
class Rep:
    """A representative hub of ``hub_templates``: its input row, its surface before collapses
    (faces, rings, CNT mesh) and its geometry (the CHoCC topology its batch shares)."""
    center: np.ndarray
    radius: float
    neighbor_centers: np.ndarray
    neighbor_radii: np.ndarray
    surface: list
    geometry: HubGeometry


def _batch_round(out, lead, hub, surface, rest, todo, centers, radii, nbc, dirs, nbr, lengths, geo, style, levels,
                 segments, min_edge, hint) -> None:
    """The hubs ``rest`` that share the topology of the representative row ``lead`` (``hub``, its
    ``surface``): batched, or built alone (from ``hint``) where the batch cannot tell their
    collapses; ``todo`` keeps the others."""
    ties = _batch_templates(out, hub, surface, np.concatenate([[lead], rest]), centers, radii, dirs, nbr,
                            lengths, geo, style, levels, segments, min_edge)
    for g in ties:  # this topology, but collapses the batch cannot tell: alone, no new batch
        out[g] = _named(g, hub_template, centers[g], radii[g], nbc[g], nbr[g], style, levels, segments, hint,
                        min_edge)
    todo[rest] = [out[g] is None for g in rest]


def _batch_templates(out, rep, surface, hubs, centers, radii, dirs, nbr, lengths, geo, style, levels, segments,
                     min_edge) -> list:
    """Fill ``out[g]`` for the hubs g of ``hubs[1:]`` that share the CNT of the representative
    ``hubs[0]`` (``rep``, with its surface ``[faces, rings, base mesh]`` before collapses).
    Returns the hubs of this CNT whose collapses the batch cannot tell (``_collapsed``)."""
    faces, rings, base = surface
    normals = unit_rows(dirs[hubs])
    full = _Batch(rep, normals, geo.alphas[hubs], geo.r_plus[hubs], geo.rho[hubs], style, segments)
    if len(base.vertices) != 3 * len(full.tris) + 2 * np.maximum(full.m[0] - 1, 0).sum():
        return []  # the representative's CNT is not its batch form (point circles, merged corridors)
    keep = np.flatnonzero(full.ok[1:]) + 1
    ties: list = []
    per_hub = len(faces) * 3  # about the vertex count after refinement, for the batch size
    step = max(1, BATCH_VERTICES // max(per_hub, 1))
    topology = None
    for lo in range(0, len(keep), step):
        sel = keep[lo:lo + step]
        batch = copy.copy(full)
        batch.take(sel)
        ids = hubs[sel]
        unit = batch.cnt_vertices()
        rp, rho = batch.r_plus, batch.rho
        # every vertex of a batch's CNT lies on a contact circle (no point circles): at its distance
        on = unit * rp[:, None, None] if not geo.pulled[ids].any() else unit * rho[:, base.vertex_circle, None]
        if style == "refined":
            verts, f, rg = refine_arrays(
                on, unit, base.faces, base.face_corridor, base.face_params, base.rings,
                dirs.shape[1], batch.normals, batch.alphas, rho, batch.corridor_point,
                lambda u, ids=ids: exit_distances(u, radii[ids], dirs[ids], nbr[ids], lengths[ids]), levels,
                batch.cors)
        else:
            verts, f, rg = on, base.faces, base.rings
        if topology is None:  # the same faces and rings for every chunk
            topology = _Surface(f, [rg[s] for s in range(len(rg))], verts.shape[1])
        surfaces = _collapsed(verts, topology, min_edge)
        caps = {}
        disk = dirs[ids] * (rho * np.cos(batch.alphas))[..., None]
        allv = np.concatenate([verts, disk], axis=1) + centers[ids][:, None]
        for k, g in enumerate(ids):
            if surfaces[k] is None:
                ties.append(g)
                continue
            fk, rk = surfaces[k]
            if id(fk) not in caps:
                caps[id(fk)] = _caps(rk[:dirs.shape[1]], verts.shape[1])
            c = Chocc(batch.normals[k], batch.alphas[k], batch.tris, batch.plane_normals[k], batch.plane_alphas[k],
                      batch.points[k], batch.cors, rep.chocc.twin, rep.chocc.rings, rep.chocc.ring_corridors)
            hub = HubGeometry(float(radii[g]), float(rp[k]), dirs[g], nbr[g], lengths[g], c, dirs.shape[1],
                              bool(geo.clean[g]), batch.alphas[k], batch.tris, rho[k] if geo.pulled[g] else None)
            if folded(np.concatenate([verts[k], disk[k]]), fk, caps[id(fk)], hub.pulled):
                hub.clean = False  # folded: as ``hub_template``
            out[g] = HubTemplate(allv[k], fk, rk[:dirs.shape[1]], caps[id(fk)], hub)
    return ties


def _edges(faces: np.ndarray) -> np.ndarray:
    return sorted_edges(faces, int(faces.max()) + 1 if len(faces) else 1)


class _Surface:
    """One surface topology of a batch: faces (F, 3) over nv vertices, rings, its edges (E, 2)
    (sorted, as ``collapse_short_edges`` lists them) and the number of faces at each vertex."""

    def __init__(self, faces: np.ndarray, rings: list, nv: int):
        self.faces = np.asarray(faces, np.int64).reshape(-1, 3)
        self.rings, self.nv = rings, nv
        self.edges = _edges(self.faces)
        self.degree = np.bincount(self.faces.ravel(), minlength=nv)

    def collapse(self, verts: np.ndarray, short: np.ndarray, tol: float, rings_deep: int = 4):
        """``collapse_short_edges`` of one hub (verts (nv, 3), its short edges ``short`` (E,)
        mask), run on the patch of faces around them: its faces are the only ones a collapse
        reads or changes as long as every vertex of a changed face, and every edge still short,
        has all its faces in the patch (then the passes take the same short edges in the same
        order). The patch grows by a ring of faces until that holds. Returns (faces: the
        untouched faces in order, then the patch's; rings; the patch's vertex ids; the trace of
        its collapse, ``collapse_short_edges``), or None where the patch would not stay local."""
        mark = np.zeros(self.nv, bool)
        mark[self.edges[short].ravel()] = True
        mark[self.faces[mark[self.faces].any(axis=1)].ravel()] = True  # a collapse's new edges reach one ring out
        for _ in range(rings_deep):
            patch = mark[self.faces].any(axis=1)
            sub = self.faces[patch]
            inner = np.bincount(sub.ravel(), minlength=self.nv) == self.degree
            trace: list = []
            f1, r1, _ = collapse_short_edges(verts, sub, self.rings, tol, trace=trace)
            gone = np.zeros(self.nv, bool)
            gone[sub.ravel()] = True
            gone[f1.ravel()] = False
            e1 = _edges(f1)
            left = e1[np.linalg.norm(verts[e1[:, 0]] - verts[e1[:, 1]], axis=1) < tol]
            if inner[sub[gone[sub].any(axis=1)]].all() and inner[left].all():
                return np.concatenate([self.faces[~patch], f1]), r1, np.unique(sub), trace
            mark[sub.ravel()] = True
        return None


def _snapped(verts: np.ndarray) -> np.ndarray:
    """Vertices (..., 3) in hub units on the SNAP grid. Short-edge collapses read only lengths,
    and their order among edges of equal length (symmetric arcs and corridors have many) would
    otherwise be decided by round-off, which differs between the batch and the per-hub path."""
    return np.round(verts / SNAP) * SNAP


def _unsure(verts: np.ndarray) -> np.ndarray:
    """Which coordinates (..., 3) lie within SNAP_GUARD of a SNAP rounding boundary (the two
    paths may snap them differently)."""
    frac = np.abs(verts / SNAP - np.floor(verts / SNAP) - 0.5)
    return frac < SNAP_GUARD / SNAP


def _collapsed(verts: np.ndarray, surface: _Surface, tol: float) -> list:
    """``collapse_short_edges`` of H hubs (verts (H, nv, 3) in hub units) with one surface
    topology on their snapped positions (as ``hub_template``): per hub (faces, rings), the same
    triangles as the collapse of the whole surface, or None where the batch cannot tell them
    (built alone): a coordinate that decides a length near ``tol`` or in a collapse's patch
    may snap otherwise on the per-hub path (``_unsure``). Hubs without short edges share the
    surface; each other hub is collapsed on the patch around its short edges
    (``_Surface.collapse``), or takes the collapse of an earlier hub whose passes it follows
    (``follows_trace``: the same short edges in the same order, so the same patch and faces)."""
    out: list = [(surface.faces, surface.rings)] * len(verts)
    if tol <= 0:
        return out
    snapped = _snapped(verts)
    unsure = _unsure(verts).any(axis=-1)  # (H, nv)
    e = surface.edges
    d = np.linalg.norm(snapped[:, e[:, 0]] - snapped[:, e[:, 1]], axis=-1)
    short = d < tol
    edge_unsure = (np.abs(d - tol) < 4 * SNAP) & (unsure[:, e[:, 0]] | unsure[:, e[:, 1]])
    done: dict = {}  # the order of a hub's short edges -> collapses (with their traces) of hubs with it
    for k in np.flatnonzero(short.any(axis=1) | edge_unsure.any(axis=1)):
        if edge_unsure[k].any():
            out[k] = None
            continue
        seen = done.setdefault(ordered_short(d[k], tol).tobytes(), [])
        local = next((c for c in seen if follows_trace(snapped[k], c[3], tol)), None)
        if local is None:
            local = surface.collapse(snapped[k], short[k], tol)
            if local is not None:
                seen.append(local)
        out[k] = None if local is None or unsure[k, local[2]].any() else local[:2]
    return out
