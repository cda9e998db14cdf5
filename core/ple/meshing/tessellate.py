"""Watertight tessellation of a lattice region from its ACHoCC (CHoCC paper 001_ §5–6).

Styles:
- ``cnt``: Crude Natural Tessellation — each hub is the CNT of its CHoCC (triangles, one
  planar quad per corridor), each beam the strip between its two contact rings;
- ``chocc``: corridors sampled as strips of cone generators (``segments`` per full circle);
- ``refined``: the CNT refined ``levels`` times (§6): split every edge, snap the midpoints of
  circle arcs onto their circle, and move every other new vertex along the ray from the
  ball's centre onto the exact lattice boundary (central projection); point circles (the
  off-centre fix) are projected too;
- ``balls-beams``: preview spheres and frusta (``ple.preview``), overlapping, not watertight.

Conforming joints: a beam's strip uses the very vertices of the rings of its two hubs, so
the region's mesh is one closed, consistently oriented 2-manifold without booleans. Beams
leaving the region are cut at the hub's contact disk, which is capped.

Steady copies (thesis §6.2.2): a hub's mesh is built once, in the template frame, per
distinct neighbourhood *seen from that frame* and mapped to the world by its group's
similarity. The neighbourhood of (i, j, k) in the frame of its group is
U^-i V^-j W^dk V^(j+dj) U^(i+di) — independent of k — so hubs are computed once per
(i, j, n) and copied along W (for commuting U, V, W, e.g. translations, once per n).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import trimesh

from ..algebra.vectors import perpendicular_frames
from ..errors import PleError
from ..model.lattice import Lattice, Region
from .achocc import HubGeometry, hub_geometry
from .chocc import ChoccMesh, cnt_segments, corridor_mesh, sampled_segments
from .fillet import filleted
from .preview import balls_beams_mesh
from .styles import DEFAULT_LEVELS, DEFAULT_SEGMENTS
from .styles import style as style_named
from .unclean import find_unclean, unite
from .weld import COLLAPSE_GRIDS, collapse_short_edges, grid_spacing

KEY_QUANTUM = 1e-9  # neighbourhoods equal to this fraction of the ball radius share a hub mesh
MAX_LEVELS = 6
MAX_CHECK_GROUPS = 500_000  # streamed regions up to this size are checked for unclean hubs first


@dataclass
class HubTemplate:
    """A hub mesh in the template frame: vertices (m, 3), outward faces (f, 3), per incident
    beam the ring of vertex ids on its contact circle (clockwise about the beam direction) and
    the fan faces capping its disk (using one extra vertex, the disk centre)."""

    vertices: np.ndarray
    faces: np.ndarray
    rings: list
    caps: list
    geometry: HubGeometry


def _refine(mesh: ChoccMesh, hub: HubGeometry, levels: int) -> tuple[np.ndarray, np.ndarray, list]:
    """§6 refinement on the unit-sphere CNT: ``levels`` 1-to-4 splits (a corridor quad,
    two triangles, becomes 8 around its centre), arc midpoints snapped to their circle, other
    new vertices centrally projected. Returns vertices in hub units (centre at 0), faces, rings.

    A new vertex is first placed on the CHoCC hull itself — on a planar triangle, or on the
    curved corridor at the mean of its corners' corridor coordinates (``ChoccMesh.corridor_point``)
    — and then projected from the centre. A point of the planar CNT quad near a long arc's chord
    lies in that circle's cone, and its projection would land on the beam beyond the contact
    disk, folding into the beam's strip; a point of the hull never does (the centre is inside
    the hull, so the cones over its faces, corridors and disks do not overlap)."""
    c = hub.chocc
    real = hub.slots
    r_plus = hub.r_plus
    hull = mesh.vertices.copy()  # positions on the CHoCC hull (unit sphere scale)
    verts = mesh.vertices * r_plus
    circle = mesh.vertex_circle.copy()
    on_circle = circle < real
    off = ~on_circle
    if off.any():  # point circles: onto the lattice too
        u = verts[off] / np.linalg.norm(verts[off], axis=1, keepdims=True)
        verts[off] = u * hub.exit_distance(u)[:, None]
    faces = mesh.faces
    fcor = mesh.face_corridor if mesh.face_corridor is not None else np.full(len(faces), -1)
    fpar = mesh.face_params if mesh.face_params is not None else np.zeros((len(faces), 3, 2))
    rings = [r.copy() for r in mesh.rings]
    frames = perpendicular_frames(c.normals)
    for _ in range(levels):
        nv = len(verts)
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        ekey = np.minimum(e[:, 0], e[:, 1]) * nv + np.maximum(e[:, 0], e[:, 1])
        uniq, inv = np.unique(ekey, return_inverse=True)
        inv = inv.reshape(-1)
        ua, ub = uniq // nv, uniq % nv
        # hull points of the face-edge midpoints: corridor coordinates on corridors, chords on triangles
        ecor = np.tile(fcor, 3)
        epar = 0.5 * (np.concatenate([fpar[:, 0], fpar[:, 1], fpar[:, 2]])
                      + np.concatenate([fpar[:, 1], fpar[:, 2], fpar[:, 0]]))
        hmid = 0.5 * (hull[e[:, 0]] + hull[e[:, 1]])
        onc = np.flatnonzero(ecor >= 0)
        if len(onc):
            hmid[onc] = mesh.corridor_point(ecor[onc], epar[onc, 0], epar[onc, 1])
        # one hull point per edge: a corridor's if any face on it is a corridor (they agree on
        # the generators shared with triangles)
        pick = np.full(len(uniq), -1)
        order = np.argsort(ecor >= 0, kind="stable")  # triangles first, corridors overwrite
        pick[inv[order]] = order
        hnew = hmid[pick]
        mids = 0.5 * (verts[ua] + verts[ub])
        new_ids = nv + np.arange(len(uniq))
        is_arc = np.zeros(len(uniq), bool)
        for ci in range(real):
            ring = rings[ci]
            if len(ring) < 2:
                continue
            x, y = ring, np.roll(ring, -1)
            q = np.searchsorted(uniq, np.minimum(x, y) * nv + np.maximum(x, y))
            is_arc[q] = True
            mids[q] = _arc_mids(verts[x], verts[y], c.normals[ci], c.alphas[ci], r_plus, frames, ci)
            hnew[q] = mids[q] / r_plus
            out = np.empty(2 * len(ring), np.int64)
            out[0::2], out[1::2] = ring, new_ids[q]
            rings[ci] = out
        proj = ~is_arc
        if proj.any():
            u = hnew[proj] / np.linalg.norm(hnew[proj], axis=1, keepdims=True)
            mids[proj] = u * hub.exit_distance(u)[:, None]
        verts = np.concatenate([verts, mids])
        hull = np.concatenate([hull, hnew])
        m = new_ids[inv].reshape(3, -1).T  # midpoints of edges 01, 12, 20 per face
        v0, v1, v2 = faces.T
        faces = np.concatenate([np.stack([v0, m[:, 0], m[:, 2]], 1), np.stack([m[:, 0], v1, m[:, 1]], 1),
                                np.stack([m[:, 2], m[:, 1], v2], 1), m])
        p0, p1, p2 = fpar[:, 0], fpar[:, 1], fpar[:, 2]
        p01, p12, p20 = 0.5 * (p0 + p1), 0.5 * (p1 + p2), 0.5 * (p2 + p0)
        fpar = np.concatenate([np.stack([p0, p01, p20], 1), np.stack([p01, p1, p12], 1),
                               np.stack([p20, p12, p2], 1), np.stack([p01, p12, p20], 1)])
        fcor = np.tile(fcor, 4)
    return verts, faces, rings


def _arc_mids(pa, pb, n, alpha, r_plus, frames, ci) -> np.ndarray:
    """Midpoints of the clockwise arcs (about n) from pa (k, 3) to pb on circle (n, alpha) of S⁺."""
    e1, e2 = frames[0][ci], frames[1][ci]
    ta, tb = np.arctan2(pa @ e2, pa @ e1), np.arctan2(pb @ e2, pb @ e1)
    d = (ta - tb) % (2 * np.pi)
    d[d > 2 * np.pi - 1e-9] = 0.0
    t = ta - d / 2
    return r_plus * (np.cos(alpha) * n + np.sin(alpha) * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2))


def hub_template(center, radius, neighbor_centers, neighbor_radii, style: str, levels: int,
                 segments: int, hint=None, min_edge: float = 0.0, fillet: float | None = None) -> HubTemplate:
    """Tessellate one junction: ball (center (3,), radius) with beams to the balls
    (neighbor_centers (S, 3), neighbor_radii (S,)), in the given style. Edges shorter than
    ``min_edge`` are collapsed (``ple.meshing.weld.collapse_short_edges``) so that the mesh keeps its
    topology when written in float32."""
    center = np.asarray(center, float)
    vec = np.asarray(neighbor_centers, float).reshape(-1, 3) - center
    lengths = np.linalg.norm(vec, axis=1)
    if np.any(lengths <= 0):
        raise PleError("a beam joins two balls with the same centre")
    dirs = vec / lengths[:, None]
    hub = hub_geometry(radius, dirs, np.asarray(neighbor_radii, float).reshape(-1), lengths, hint)
    hub = filleted(hub, fillet)  # optional junction fillet (001_ §6 Eq. 6): projection onto the blend
    if style == "refined":
        base = corridor_mesh(hub.chocc, cnt_segments)
        verts, faces, rings = _refine(base, hub, levels)
    else:
        base = corridor_mesh(hub.chocc, cnt_segments if style == "cnt" else sampled_segments(segments))
        verts, faces, rings = base.vertices * hub.r_plus, base.faces, base.rings
    if min_edge > 0:
        faces, rings, _ = collapse_short_edges(verts, faces, rings, min_edge)
    axial = hub.r_plus * np.cos(hub.alphas)
    caps = []
    all_verts = [verts]
    nv = len(verts)
    for s in range(hub.slots):
        q = rings[s][::-1]  # counter-clockwise about the beam: the disk's outward orientation
        all_verts.append((dirs[s] * axial[s])[None])
        caps.append(np.stack([np.full(len(q), nv), q, np.roll(q, -1)], axis=1))
        nv += 1
    return HubTemplate(np.concatenate(all_verts) + center, faces, [rings[s] for s in range(hub.slots)], caps, hub)


def zipper(angles_a: np.ndarray, angles_b: np.ndarray) -> np.ndarray:
    """Strip between two closed rings listed counter-clockwise about the beam axis, ring A at
    the near end, B at the far end, with angles (radians) about the axis.

    Returns faces (ma + mb, 3, 2) of (ring, index) pairs, ring 0 = A, 1 = B, oriented with
    outward normals: the beam traverses A counter-clockwise and B clockwise (the reverse of
    the hubs' rings), so the strip and the hubs close up (§6: a triangle strip choosing the
    next sample on one ring or the other by angle)."""
    ma, mb = len(angles_a), len(angles_b)
    two_pi = 2 * np.pi
    pa = _unwrap_ring(angles_a)
    rel = (angles_b - angles_a[0] + np.pi) % two_pi - np.pi
    b0 = int(np.argmin(np.round(np.abs(rel), 9)))
    order_b = (np.arange(mb) + b0) % mb
    pb = rel[b0] + _unwrap_ring(angles_b[order_b])
    key_a = np.append(pa[1:], two_pi)  # a-event s (1..ma): reach A[s]
    key_b = np.append(pb[1:], rel[b0] + two_pi)
    keys = np.round(np.concatenate([key_a, key_b]), 9)  # equal angles (symmetric rings) tie robustly
    is_b = np.concatenate([np.zeros(ma, bool), np.ones(mb, bool)])
    order = np.lexsort((is_b, keys))
    is_b = is_b[order]
    seen_b = np.cumsum(is_b) - is_b  # b-events before each event
    seen_a = np.cumsum(~is_b) - ~is_b
    faces = np.zeros((ma + mb, 3, 2), np.int64)
    # a-event s: (A[s-1], A[s], B[seen_b]); b-event t: (B[t], B[t-1], A[seen_a])
    sa = seen_a + 1
    tb = seen_b + 1
    fa = ~is_b
    faces[fa, 0] = np.stack([np.zeros(fa.sum(), np.int64), (sa[fa] - 1) % ma], 1)
    faces[fa, 1] = np.stack([np.zeros(fa.sum(), np.int64), sa[fa] % ma], 1)
    faces[fa, 2] = np.stack([np.ones(fa.sum(), np.int64), order_b[seen_b[fa] % mb]], 1)
    fb = is_b
    faces[fb, 0] = np.stack([np.ones(fb.sum(), np.int64), order_b[tb[fb] % mb]], 1)
    faces[fb, 1] = np.stack([np.ones(fb.sum(), np.int64), order_b[(tb[fb] - 1) % mb]], 1)
    faces[fb, 2] = np.stack([np.zeros(fb.sum(), np.int64), seen_a[fb] % ma], 1)
    return faces


class _Tessellator:
    """Builds region meshes box by box, caching hub templates and beam strips."""

    def __init__(self, lat: Lattice, region: Region, style: str, levels: int, segments: int,
                 fillet: float | None = None):
        lat.validate()
        self.fillet = fillet
        self.lat, self.region, self.style, self.levels, self.segments = lat, region, style, levels, segments
        nn = len(lat.nodes)
        # slots of template node n: (pattern, +1 outgoing | -1 incoming)
        self.slots = [[(p, 1) for p, b in enumerate(lat.beams) if b.n1 == n]
                      + [(p, -1) for p, b in enumerate(lat.beams) if b.n2 == n] for n in range(nn)]
        self.templates: dict = {}
        self.strips: dict = {}
        self.hints: dict = {}
        self.scale = lat.template_radii * KEY_QUANTUM
        # float32-safe output: edges shorter than a few float32 grid steps of the region's size
        # are collapsed in the hub templates (template units: divided by the smallest group scale)
        self.grid = output_grid(lat, region)
        corners = np.array([[i, j, k] for i in (region.i0, max(region.i1 - 1, region.i0))
                            for j in (region.j0, max(region.j1 - 1, region.j0))
                            for k in (region.k0, max(region.k1 - 1, region.k0))])
        fmin = float(np.min(lat.group_factors(corners[:, 0], corners[:, 1], corners[:, 2])))
        self.min_edge = COLLAPSE_GRIDS * self.grid / fmin
        self.excluded = None  # sorted linear keys of nodes meshed elsewhere (``ple.meshing.unclean``)

    def _key(self, idx: np.ndarray) -> np.ndarray:
        _, nv, nw = self.lat.counts
        nn = len(self.lat.nodes)
        return ((idx[..., 0] * nv + idx[..., 1]) * nw + idx[..., 2]) * nn + idx[..., 3]

    def is_excluded(self, idx: np.ndarray) -> np.ndarray:
        """Which nodes idx (..., 4) are left to the union of unclean neighbourhoods: for the fast
        mesh they lie outside the region (their beams end in capped contact disks)."""
        if self.excluded is None or idx.size == 0:
            return np.zeros(idx.shape[:-1], bool)
        return np.isin(self._key(idx), self.excluded)

    def find_unclean(self):
        """The region's unclean hubs (``ple.meshing.unclean.find_unclean``) with r⁺ and the ACHoCC's
        clean flag of every hub from its template. Returns (report, evaluation)."""
        ev = self.lat.evaluate(self.region)
        idx = np.asarray(ev.node_index, np.int64)
        if len(idx) == 0:
            return find_unclean(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 2)), np.zeros(0)), ev
        tids, _, _, _ = self.instances(idx)
        by_id = {v[0]: v[1] for v in self.templates.values()}
        rp_t = np.array([by_id[t].geometry.r_plus for t in range(len(by_id))])
        clean_t = np.array([bool(by_id[t].geometry.clean) for t in range(len(by_id))])
        f = self.lat.group_factors(idx[:, 0], idx[:, 1], idx[:, 2])
        return find_unclean(ev.center, ev.radius, ev.beam_nodes, rp_t[tids] * f, ~clean_t[tids]), ev

    # ----- hubs -----------------------------------------------------------------------
    def _neighbors(self, idx: np.ndarray, n: int):
        """For nodes idx (N, 4) of template node n: neighbour index (N, S, 4), exists (N, S), in region (N, S)."""
        lat, r = self.lat, self.region
        out = []
        for p, sign in self.slots[n]:
            b = lat.beams[p]
            off = np.array([b.di, b.dj, b.dk]) * sign
            other = b.n2 if sign > 0 else b.n1
            nb = np.concatenate([idx[:, :3] + off, np.full((len(idx), 1), other)], axis=1)
            out.append(nb)
        nb = np.stack(out, axis=1) if out else np.zeros((len(idx), 0, 4), np.int64)
        counts = np.array(lat.counts)
        exists = np.all((nb[..., :3] >= 0) & (nb[..., :3] < counts), axis=-1)
        if lat.filter is not None and exists.any():
            exists[exists] = lat.keeps(nb[exists])  # thesis §9: a beam to a filtered-out node does not exist
        lo = np.array([r.i0, r.j0, r.k0])
        hi = np.array([r.i1, r.j1, r.k1])
        inside = np.all((nb[..., :3] >= lo) & (nb[..., :3] < hi), axis=-1) & ~self.is_excluded(nb)
        return nb, exists, inside

    def instances(self, idx: np.ndarray):
        """Hub templates for nodes idx (N, 4): template ids (N,), group matrices (N, 4, 4),
        inverse matrices, and per template node (rows, neighbour index, exists, in region).

        Steady copies: the neighbourhood seen from a hub's own frame does not depend on k, so
        signatures are computed for one representative per (i, j, n, set of existing beams)
        and every other hub of that column is a copy along W."""
        lat = self.lat
        m = lat.group_matrices(idx[:, 0], idx[:, 1], idx[:, 2])
        minv = _similarity_inverse(m)
        tids = np.zeros(len(idx), np.int64)
        info = {}
        nv = lat.counts[1]
        for n in range(len(lat.nodes)):
            sel = np.flatnonzero(idx[:, 3] == n)
            if len(sel) == 0:
                continue
            nb, exists, inside = self._neighbors(idx[sel], n)
            info[n] = (sel, nb, exists, inside)
            s = nb.shape[1]
            bits = (exists.astype(np.int64) << np.arange(s, dtype=np.int64)).sum(axis=1) if s else 0
            col = idx[sel, 0] * nv + idx[sel, 1]
            if lat.radius_field is not None:  # graded radii: hubs along W are not copies of each other
                col = np.arange(len(sel), dtype=np.int64)
            _, rep, inv = np.unique(col * (1 << s) + bits, return_index=True, return_inverse=True)
            reps = sel[rep]
            local = np.full((len(reps), s, 4), np.nan)
            if s:
                ex = exists[rep]
                flat_nb = nb[rep].reshape(-1, 4)
                ok = ex.reshape(-1)
                c = np.zeros((len(flat_nb), 3))
                rad = np.zeros(len(flat_nb))
                if ok.any():
                    c[ok], rad[ok] = lat.node_balls(flat_nb[ok])
                c = c.reshape(len(reps), s, 3)
                f = lat.group_factors(idx[reps, 0], idx[reps, 1], idx[reps, 2])
                local[..., :3] = np.einsum("nab,nsb->nsa", minv[reps, :3, :3], c) + minv[reps, None, :3, 3]
                local[..., 3] = rad.reshape(len(reps), s) / f[:, None]
                local[~ex] = np.nan
            q = np.where(np.isnan(local), -(2**62), np.round(local / self.scale[n])).astype(np.int64)
            own = np.full(len(reps), lat.template_radii[n])
            if lat.radius_field is not None:  # the hub's own graded radius, in its frame
                own = lat.node_balls(idx[reps])[1] / lat.group_factors(idx[reps, 0], idx[reps, 1], idx[reps, 2])
            own_q = np.round(own / self.scale[n]).astype(np.int64)
            rep_tid = np.zeros(len(reps), np.int64)
            for u in range(len(reps)):
                key = (n, q[u].tobytes(), int(own_q[u]))
                if key not in self.templates:
                    have = ~np.isnan(local[u, :, 3])
                    hint_key = (n, have.tobytes())  # the last hub with these beams: likely the same hull
                    tpl = hub_template(lat.template_centers[n], float(own[u]), local[u, have, :3],
                                       local[u, have, 3], self.style, self.levels, self.segments,
                                       self.hints.get(hint_key), self.min_edge, self.fillet)
                    self.hints[hint_key] = tpl.geometry.base_triangles
                    slot_of = np.cumsum(have) - 1
                    self.templates[key] = (len(self.templates), tpl, np.where(have, slot_of, -1))
                rep_tid[u] = self.templates[key][0]
            tids[sel] = rep_tid[inv.reshape(-1)]
        return tids, m, minv, info

    # ----- assembly ---------------------------------------------------------------------
    def build(self, box: Region) -> tuple[np.ndarray, np.ndarray]:
        """Vertices and faces of the hubs of ``box`` and of the beams from them (to balls in
        the region), with capped disks where a beam leaves the region."""
        lat = self.lat
        nn = len(lat.nodes)
        own = box.node_index(nn)
        own = own[self.lat.keeps(own) & ~self.is_excluded(own)]
        # ghosts: the far ends of beams leaving the box but not the region
        ghosts = []
        for b in lat.beams:
            src = own[own[:, 3] == b.n1]
            dst = np.concatenate([src[:, :3] + [b.di, b.dj, b.dk], np.full((len(src), 1), b.n2)], axis=1)
            ok = _in(dst, self.region) & ~_in(dst, box) & ~self.is_excluded(dst)
            ok[ok] = self.lat.keeps(dst[ok])
            ghosts.append(dst[ok])
        ghosts = np.unique(np.concatenate(ghosts), axis=0) if ghosts else np.zeros((0, 4), np.int64)
        idx = np.concatenate([own, ghosts]).astype(np.int64)
        n_own = len(own)
        tids, m, minv, info = self.instances(idx)
        tpl_list = {v[0]: (v[1], v[2]) for v in self.templates.values()}
        sizes = np.array([len(tpl_list[t][0].vertices) for t in range(len(tpl_list))])
        order = np.argsort(tids, kind="stable")
        starts = np.concatenate([[0], np.cumsum(sizes[tids[order]])])
        offsets = np.zeros(len(idx), np.int64)
        offsets[order] = starts[:-1]
        verts = np.empty((int(starts[-1]), 3))
        faces = []
        ut, first = np.unique(tids[order], return_index=True)
        for t, lo, hi in zip(ut, first, np.append(first[1:], len(order))):
            inst = order[lo:hi]
            tpl = tpl_list[t][0]
            v = np.einsum("nab,mb->nma", m[inst, :3, :3], tpl.vertices) + m[inst, None, :3, 3]
            verts[starts[lo]:starts[hi]] = v.reshape(-1, 3)  # the block of template t is contiguous
            mine = inst[inst < n_own]
            if len(mine):
                faces.append((tpl.faces[None] + offsets[mine][:, None, None]).reshape(-1, 3))
        # caps where a beam leaves the region
        for sel, nb, exists, inside in info.values():
            own_sel = sel < n_own
            for s in range(nb.shape[1]):
                cut = sel[own_sel & exists[:, s] & ~inside[:, s]]
                for t in np.unique(tids[cut]):
                    inst = cut[tids[cut] == t]
                    tpl, slot_of = tpl_list[t]
                    cap = tpl.caps[slot_of[s]]
                    faces.append((cap[None] + offsets[inst][:, None, None]).reshape(-1, 3))
        faces += self._beams(idx, n_own, tids, m, minv, offsets, tpl_list)
        faces = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
        return verts, faces

    def _beams(self, idx, n_own, tids, m, minv, offsets, tpl_list) -> list:
        """Strips of the beams leaving the box's hubs; one zipper per (pattern, hub templates,
        relative similarity of the two frames) — the latter depends on (i, j) only."""
        lat = self.lat
        nu, nv, nw = lat.counts
        nn = len(lat.nodes)
        lin = ((idx[:, 0] * nv + idx[:, 1]) * nw + idx[:, 2]) * nn + idx[:, 3]
        srt = np.argsort(lin)
        n_tpl = max(len(tpl_list), 1)
        out = []
        for p, b in enumerate(lat.beams):
            src = np.flatnonzero(idx[:n_own, 3] == b.n1)
            dst_idx = np.concatenate([idx[src, :3] + [b.di, b.dj, b.dk], np.full((len(src), 1), b.n2)], axis=1)
            ok = _in(dst_idx, self.region) & ~self.is_excluded(dst_idx)
            ok[ok] = self.lat.keeps(dst_idx[ok])
            src, dst_idx = src[ok], dst_idx[ok]
            if len(src) == 0:
                continue
            dl = ((dst_idx[:, 0] * nv + dst_idx[:, 1]) * nw + dst_idx[:, 2]) * nn + dst_idx[:, 3]
            dst = srt[np.searchsorted(lin[srt], dl)]
            slot_a = self.slots[b.n1].index((p, 1))
            slot_b = self.slots[b.n2].index((p, -1))
            col = idx[src, 0] * nv + idx[src, 1]
            gkey = (tids[src] * n_tpl + tids[dst]) * (nu * nv) + col
            _, first, inv = np.unique(gkey, return_index=True, return_inverse=True)
            inv = inv.reshape(-1)
            order = np.argsort(inv, kind="stable")
            bounds = np.searchsorted(inv[order], np.arange(len(first) + 1))
            for u in range(len(first)):
                sel = order[bounds[u]:bounds[u + 1]]
                a0, b0 = src[first[u]], dst[first[u]]
                ta, sa_map = tpl_list[tids[a0]]
                tb, sb_map = tpl_list[tids[b0]]
                ring_a = ta.rings[sa_map[slot_a]]
                ring_b = tb.rings[sb_map[slot_b]]
                rel = minv[a0] @ m[b0]
                key = (p, int(tids[a0]), int(tids[b0]), np.round(rel[:3] / 1e-9).astype(np.int64).tobytes())
                if key not in self.strips:
                    self.strips[key] = _strip(ta, ring_a, tb, ring_b, rel,
                                              lat.template_centers[b.n1], lat.template_centers[b.n2])
                f = self.strips[key]
                which, li = f[..., 1], f[..., 0]
                local = np.where(which == 0, ring_a[np.where(which == 0, li, 0)], ring_b[np.where(which == 1, li, 0)])
                base = np.where(which[None] == 0, offsets[src[sel]][:, None, None], offsets[dst[sel]][:, None, None])
                out.append((base + local[None]).reshape(-1, 3))
        return out


def _unwrap_ring(theta: np.ndarray) -> np.ndarray:
    """Angles of a counter-clockwise ring relative to its first vertex, non-decreasing
    (coincident vertices whose round-off steps slightly backwards count as zero steps)."""
    step = np.diff(theta) % (2 * np.pi)
    step[step > 2 * np.pi - 1e-9] = 0.0
    return np.concatenate([[0.0], np.cumsum(step)])


def _strip(ta: HubTemplate, ring_a, tb: HubTemplate, ring_b, rel, ca, cb) -> np.ndarray:
    """Beam strip faces (k, 3, 2) as (local ring index, ring 0|1), computed in hub A's frame."""
    pa = ta.vertices[ring_a]
    pb = tb.vertices[ring_b] @ rel[:3, :3].T + rel[:3, 3]
    cb_local = rel[:3, :3] @ cb + rel[:3, 3]
    d = cb_local - ca
    d /= np.linalg.norm(d)
    e1, e2 = perpendicular_frames(d[None])
    ang = lambda p: np.arctan2((p - ca) @ e2[0], (p - ca) @ e1[0])  # noqa: E731
    a_ccw = np.arange(len(ring_a))[::-1]  # hub rings run clockwise about their outward normal
    f = zipper(ang(pa[a_ccw]), ang(pb))
    out = np.empty_like(f)
    out[..., 1] = f[..., 0]
    out[..., 0] = np.where(f[..., 0] == 0, a_ccw[np.where(f[..., 0] == 0, f[..., 1], 0)], f[..., 1])
    return out


def _similarity_inverse(m: np.ndarray) -> np.ndarray:
    """Inverses of similarity matrices (N, 4, 4): (sR)^-1 = (sR)^T / s²."""
    lin = m[:, :3, :3]
    s2 = np.einsum("nij,nij->n", lin, lin) / 3.0
    inv = np.zeros_like(m)
    inv[:, :3, :3] = lin.transpose(0, 2, 1) / s2[:, None, None]
    inv[:, :3, 3] = -np.einsum("nij,nj->ni", inv[:, :3, :3], m[:, :3, 3])
    inv[:, 3, 3] = 1.0
    return inv


def _in(idx: np.ndarray, r: Region) -> np.ndarray:
    return ((idx[:, 0] >= r.i0) & (idx[:, 0] < r.i1) & (idx[:, 1] >= r.j0) & (idx[:, 1] < r.j1)
            & (idx[:, 2] >= r.k0) & (idx[:, 2] < r.k1))


MAX_FILLET = 10.0  # ball radii: a blend far beyond the ball is no junction fillet (and b = ln 2 / (s r) underflows)


def check_fillet(fillet, style: str):
    """A fillet (size in ball radii, 0 < size <= MAX_FILLET) shapes only the refined style's
    projected vertices; None when there is none."""
    if fillet is None or fillet == 0:  # 0: none
        return None
    if not (math.isfinite(fillet) and 0 < fillet <= MAX_FILLET):
        raise PleError(f"--fillet {fillet}: expected a size in ball radii in (0, {MAX_FILLET:g}]")
    if style != "refined":
        raise PleError(f"--fillet: a fillet needs the refined style, not {style!r}")
    return float(fillet)


_check_fillet = check_fillet


def _check_style(style: str, levels: int | None, segments: int | None) -> tuple[int, int]:
    style_named(style)
    levels = DEFAULT_LEVELS if levels is None else int(levels)
    segments = DEFAULT_SEGMENTS if segments is None else int(segments)
    if not 0 <= levels <= MAX_LEVELS:
        raise PleError(f"levels {levels}: expected 0..{MAX_LEVELS}")
    if not 3 <= segments <= 1024:
        raise PleError(f"segments {segments}: expected 3..1024")
    return levels, segments


def tessellation_box(lat: Lattice, region, box, style: str = "refined", levels: int | None = None,
                     segments: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3) of the hubs of one ``box`` of ``region`` (and of the
    beams from them, capped where a beam leaves the region): a part of a partitioned mesh. Boxes
    of one region close up exactly as the streamed tessellation's do (``iter_triangles``)."""
    levels, segments = _check_style(style, levels, segments)
    if style == "balls-beams":
        raise PleError("boxes of a mesh need a closed style (refined, cnt or chocc)")
    r = lat.region(region)
    return _Tessellator(lat, r, style, levels, segments).build(lat.region(box))


def tessellate(lat: Lattice, region=None, style: str = "refined", levels: int | None = None,
               segments: int | None = None, check_clean: bool = True, fillet: float | None = None) -> trimesh.Trimesh:
    """The mesh of a region (default: the whole lattice) as one trimesh.

    ``levels``: refinement levels of ``refined`` (default 4); ``segments``: generators per full
    circle of ``chocc`` corridors (default 16). Watertight and consistently oriented for
    chocc, cnt and refined; ``balls-beams`` is a preview.

    Unclean hubs (``ple.meshing.unclean``) are found first (``check_clean``); if there are any, the
    clean rest is meshed on the fast path and united with their balls and beams by manifold3d;
    ``mesh.metadata["ple_unclean"]`` holds the report (None when not checked)."""
    levels, segments = _check_style(style, levels, segments)
    r = lat.region(region)
    if lat.group_map is not None:  # groups not similar (Möbius, warps): the general per-hub path
        lat = lat.explicit(r)
        r = lat.region()
    if style == "balls-beams":

        ev = lat.evaluate(r)
        return balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes)
    tess = _Tessellator(lat, r, style, levels, segments, _check_fillet(fillet, style))
    report = None
    if check_clean:
        report, ev = tess.find_unclean()
    if report is not None and len(report.nodes):
        verts, faces = build_with_unions(tess, ev, report.nodes)
    else:
        verts, faces = tess.build(r)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    mesh.remove_unreferenced_vertices()
    mesh.metadata["ple_unclean"] = report
    return mesh


def build_with_unions(tess: _Tessellator, ev, nodes) -> tuple[np.ndarray, np.ndarray]:
    """The region's mesh with the hubs ``nodes`` (rows of the evaluation ``ev``) left out of the
    fast path and united with their balls and beams by manifold3d (``ple.meshing.unclean.unite``)."""
    tess.excluded = np.unique(tess._key(np.asarray(ev.node_index, np.int64)[nodes]))
    verts, faces = tess.build(tess.region)
    used = np.unique(faces)
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return unite(verts[used], remap[faces], ev.center, ev.radius, ev.beam_nodes, nodes)


def iter_triangles(lat: Lattice, region=None, style: str = "refined", levels: int | None = None,
                   segments: int | None = None, max_groups: int = 1 << 14, fillet: float | None = None, _tess=None):
    """Stream the region's mesh box by box (bounded memory) as pairs (vertices (V, 3), faces
    (k, 3)); hubs next to a box boundary are repeated in both boxes (their vertices, not faces)."""
    levels, segments = _check_style(style, levels, segments)
    r = lat.region(region)
    if lat.group_map is not None:  # groups not similar (Möbius, warps): the general per-hub path
        lat = lat.explicit(r)
        r = lat.region()
    if style == "balls-beams":
        mesh = tessellate(lat, r, style)
        yield np.asarray(mesh.vertices), np.asarray(mesh.faces)
        return
    tess = _tess if _tess is not None else _Tessellator(lat, r, style, levels, segments, _check_fillet(fillet, style))
    boxes = list(lat.iter_slabs(max_groups=max_groups, region=r))
    # build the next box in a worker thread while the caller writes this one (numpy releases
    # the GIL in its large array operations): at most two boxes are held at a time
    with ThreadPoolExecutor(max_workers=1) as pool:
        pending = pool.submit(tess.build, boxes[0]) if boxes else None
        for nxt in boxes[1:] + [None]:
            done = pending.result()
            pending = pool.submit(tess.build, nxt) if nxt is not None else None
            yield done


def weld_chunks(chunks) -> tuple[np.ndarray, np.ndarray]:
    """One mesh (vertices (V, 3), faces (F, 3)) from the boxes of ``iter_triangles``: the hub
    vertices repeated in neighbouring boxes are bit-identical and are merged; vertices no face
    uses are dropped (the vertex set of ``tessellate`` for the same region)."""
    chunks = [(np.asarray(v, dtype=float).reshape(-1, 3), np.asarray(f, dtype=np.int64).reshape(-1, 3))
              for v, f in chunks]
    if not chunks:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    offsets = np.cumsum([0] + [len(v) for v, _ in chunks])[:-1]
    verts = np.concatenate([v for v, _ in chunks])
    faces = np.concatenate([f + o for (_, f), o in zip(chunks, offsets)])
    _, first, inverse = np.unique(verts, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")  # vertices keep the order in which boxes produced them
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    faces = rank[inverse.reshape(-1)][faces]
    used = np.zeros(len(order), dtype=bool)
    used[faces.reshape(-1)] = True
    renumber = np.cumsum(used) - 1
    return verts[first[order]][used], renumber[faces]


def output_grid(lat: Lattice, region=None) -> float:
    """The float32 snap grid of a region's output (``ple.meshing.weld.grid_spacing`` of its
    bounds): one grid for every streamed box and every job part of the region, so they close up."""
    return grid_spacing(*lat.bounds(lat.region(region)))


def checked_stream(lat: Lattice, region=None, style: str = "refined", levels: int | None = None,
                   segments: int | None = None, max_groups: int = 1 << 14, fillet: float | None = None):
    """The streamed mesh of a region (``iter_triangles``) if it has no unclean hubs: (report,
    chunks). Regions up to MAX_CHECK_GROUPS groups are checked first (``ple.meshing.unclean``;
    the check's hub templates are reused by the stream); report is None for larger regions
    (not checked). chunks is None when the region has unclean hubs: it must be meshed in memory
    with its unions (``tessellate``)."""
    levels, segments = _check_style(style, levels, segments)
    if style == "balls-beams":
        raise PleError("a checked stream needs a closed style (refined, cnt or chocc)")
    r = lat.region(region)
    tess = _Tessellator(lat, r, style, levels, segments, _check_fillet(fillet, style))
    report = tess.find_unclean()[0] if r.groups <= MAX_CHECK_GROUPS else None
    if report is not None and len(report.nodes):
        return report, None
    return report, iter_triangles(lat, r, style, levels, segments, max_groups, _tess=tess)
