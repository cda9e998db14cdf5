"""Local unions of an unclean lattice, streamed beside its clean boxes.

``find_unclean`` (``ple.meshing.unclean``) gives the element pairs whose meshes may meet
(hub-hub, hub-beam, beam-beam, not incident) and the hubs whose ACHoCC shrank its caps. The union
of a lattice is local: what is near an element depends only on the elements that reach it. So
the unclean part is split into *clusters*, the connected groups of the overlap graph:

- the hubs of a cluster (E: shrunk, or in a pair as a hub) are meshed as their balls;
- its beams (B: in a pair as a beam, or incident to a hub of E) as the convex hull of their two
  ends, each end either a ball of E or the contact ring of a clean junction;
- everything else stays on the fast, boolean-free path (``ple.meshing.tessellate``), which
  leaves the rings of B's beams open (no cap, no strip).

Each cluster is one small manifold3d union; its faces on those rings (the ring polygons, which
nothing else touches: whatever would have touched them is in the cluster) are removed, and the
ring vertices are the very floats the fast path places (``assembly.place``), so the two meet
exactly along the rings: one closed, oriented surface, without a global Boolean. The union's
faces are put on the float32 output grid (``unclean.on_grid``) with the ring vertices pinned,
and checked there for self-intersections (exact), piece by piece.

Memory and time grow with the largest cluster, not with the lattice: a crossing pair of
diagonals is a cluster of two beams. ``piece_estimate`` gives both before any union is made.
"""

from __future__ import annotations

import math
import multiprocessing
import os
from dataclasses import dataclass, field

import numpy as np

from ..algebra.elements import segment_distance
from ..algebra.vectors import perpendicular_frames, runs
from ..errors import PleError
from .selfcheck import search_cell, self_intersections
from .unclean import (
    BALL_TURNS,
    SPHERE_SEGMENTS,
    TURN_TRIES,
    component_labels,
    match_rows,
    on_grid,
    on_one_ring,
    ring_of_vertices,
)
from .weld import COLLAPSE_GRIDS, snap

UNION_TRIANGLE_BYTES = 600  # peak bytes per input triangle of a manifold3d union and its repair (measured, rounded up)


class RingTouchedError(PleError):
    """A cluster's union changed one of the contact rings it shares with the fast path: something
    of the cluster reaches that clean junction. ``ring``: the rings, [(beam row, end 0|1), …]."""

    def __init__(self, message: str, ring):
        super().__init__(message)
        self.ring = ring

    def __reduce__(self):  # from the child process of ``unite_stoppable``
        return RingTouchedError, (str(self), self.ring)


CUT = 2  # the end of a ring key (beam row, CUT) naming the ring where a cluster's beam is cut


@dataclass
class Cluster:
    """One local union: hubs (rows of the evaluation) meshed as balls, beams (rows) as hulls,
    and halves (H, 2: beam row, end 0|1) of beams cut across (``split``): the hull of the ball
    at that end and the beam's cut ring, whose key in the rings is (beam row, CUT). ``segments``:
    of its polygonal balls and cut rings (``unclean.ball_segments`` of the mesh's)."""

    hubs: np.ndarray
    beams: np.ndarray
    halves: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    segments: int = SPHERE_SEGMENTS


def clusters(report, beam_nodes, center=None, radius=None, segments: int = SPHERE_SEGMENTS) -> list:
    """The clusters of an unclean report (``find_unclean``): connected groups of the graph whose
    vertices are the elements of E and B (module docstring) and whose edges are the overlapping
    pairs and the incidences of E's hubs. beam_nodes (M, 2) node rows. With the balls (center
    (N, 3), radius (N,)) and the report's r⁺, a clean hub whose S⁺ a neighbouring ball of E
    reaches (its contact disk towards that ball is not safe from it) joins E, until none does.
    ``segments``: the clusters' (``Cluster``)."""
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    n, m = len(report.shrunk), len(bn)
    pairs = np.asarray(report.element_pairs, np.int64).reshape(-1, 2)
    hub_e = report.shrunk.copy()
    hub_e[pairs[pairs < n]] = True
    if center is not None and report.r_plus is not None and len(bn):
        c, rad = np.asarray(center, float), np.asarray(radius, float)
        reach = np.linalg.norm(c[bn[:, 0]] - c[bn[:, 1]], axis=1)
        for _ in range(n):
            grow = np.zeros(n, bool)
            for a, b in ((0, 1), (1, 0)):  # a clean at end a, a ball of E at end b reaching a's S⁺
                x, y = bn[:, a], bn[:, b]
                hit = ~hub_e[x] & hub_e[y] & (reach - rad[y] <= report.r_plus[x])
                grow[x[hit]] = True
            if not grow.any():
                break
            hub_e |= grow
    beam_b = np.zeros(m, bool)
    beam_b[pairs[pairs >= n] - n] = True
    incident = hub_e[bn[:, 0]] | hub_e[bn[:, 1]]
    beam_b |= incident
    if not hub_e.any() and not beam_b.any():
        return []
    rows = np.flatnonzero(incident)
    edges = np.concatenate([pairs, np.stack([bn[rows, 0], n + rows], 1), np.stack([bn[rows, 1], n + rows], 1)])
    label = component_labels(n + m, edges[np.concatenate([hub_e, beam_b])[edges].all(axis=1)])
    members = np.flatnonzero(np.concatenate([hub_e, beam_b]))
    order = members[np.argsort(label[members], kind="stable")]
    cuts = np.flatnonzero(np.diff(label[order])) + 1
    return [Cluster(c[c < n], c[c >= n] - n, segments=segments) for c in np.split(order, cuts)]


def cut_bound(segments: int) -> float:
    """A polygonal ball of ``segments`` (``unit_ball``: its vertices on a sphere scaled to the exact
    volume, 1.0076 at 32 segments, 1.030 at 16), or a beam's polygon, lies within this times its
    radius: 1/cos²(π/segments) bounds the scale, and 1.02 is kept as the least."""
    return max(1.02, 1.0 / math.cos(math.pi / segments) ** 2)


def split(cluster: Cluster, report, center, radius, beam_nodes, margin: float = 0.0, linear=None):
    """A cluster cut across some of its beams into smaller ones, or None (no cut, or one piece).

    A beam between two hubs of the cluster that overlaps nothing it does not share a ball with
    (it is in none of ``report``'s element pairs) is cut by the plane normal to it halfway along
    its bare part, when each half clears what the other end brings (§3: a beam is the hull of its
    two balls; the half at a ball is the hull of that ball and the cut ring): the other end's ball
    and its other beams, each taken as a capsule (segment, radius × ``cut_bound``), the half as
    the capsule of its frustum, more than ``margin`` apart. Everything else a half could meet
    shares no ball with the beam and is in a pair with it, so it is not cut. The pieces are the
    connected groups of hubs, beams and halves (pairs and incidences); a beam whose halves land in
    one piece stays whole. Returns (clusters, cut rings {(beam row, CUT): (cluster.segments, 3)}):
    each ring lies on the tangent cone of the beam, and both halves' unions take it as their
    rim, so they meet exactly there. ``linear(rows)`` (K, 3, 3): the linear part of the similarity
    that places each beam's group; a ring's first vertex is then chosen in the group's own frame,
    so the rings of copies of a cluster (along a rotation, a screw) are copies, vertex for vertex,
    and so are the pieces (``ShapeCache``'s turned copies). Without it, in world axes."""
    hubs = np.sort(np.asarray(cluster.hubs, np.int64))
    if len(hubs) < 2 or len(cluster.halves):
        return None
    c, rad = np.asarray(center, float), np.asarray(radius, float)
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    n = len(report.shrunk)
    beams = np.asarray(cluster.beams, np.int64)
    ends = bn[beams]
    inner = np.isin(ends, hubs).all(axis=1) & (ends[:, 0] != ends[:, 1]) & ~np.isin(beams, report.paired_beams())
    rings = {(j, CUT): r for j, r in _cut_rings(beams[inner], c, rad, bn, beams, margin, cluster.segments,
                                                linear).items()}
    if not rings:
        return None
    cut = np.array(sorted(j for j, _ in rings), np.int64)
    whole = np.setdiff1d(beams, cut)
    halves = np.stack([np.repeat(cut, 2), np.tile([0, 1], len(cut))], axis=1)
    # elements numbered hubs, whole beams, halves; edges: the pairs inside the cluster, incidences
    h, w = len(hubs), len(whole)
    ids = np.concatenate([hubs, n + whole])  # find_unclean's element ids of ours (sorted: hubs < n)
    pairs = np.searchsorted(ids, report.pairs_within(ids))
    own = np.isin(bn[whole], hubs)
    edges = np.concatenate([pairs,
                            np.stack([np.repeat(h + np.arange(w), 2)[own.reshape(-1)],
                                      np.searchsorted(hubs, bn[whole][own])], 1),
                            np.stack([h + w + np.arange(len(halves)),
                                      np.searchsorted(hubs, bn[halves[:, 0], halves[:, 1]])], 1)])
    label = component_labels(h + w + len(halves), edges)
    count = int(label.max()) + 1
    if count == 1:
        return None
    out = []
    for g in range(count):
        hv = halves[label[h + w:] == g]
        both = np.unique(hv[:, 0], return_counts=True)
        both = both[0][both[1] == 2]  # both halves here: the beam stays whole
        out.append(Cluster(hubs[label[:h] == g], np.sort(np.concatenate([whole[label[h:h + w] == g], both])),
                           hv[~np.isin(hv[:, 0], both)], cluster.segments))
    used = {j for piece in out for j, _ in piece.halves.tolist()}
    return out, {k: r for k, r in rings.items() if k[0] in used}


def _cut_ring(j: int, c, rad, bn, beams, margin: float, segments: int = SPHERE_SEGMENTS, linear=None):
    """The cut ring of beam j (``split``), or None when its halves do not clear the other end."""
    return _cut_rings(np.array([j], np.int64), c, rad, bn, beams, margin, segments, linear).get(int(j))


def _cut_rings(js: np.ndarray, c, rad, bn, beams, margin: float, segments: int = SPHERE_SEGMENTS,
               linear=None) -> dict:
    """The cut rings of the beams ``js`` of a cluster (its ``beams``) whose halves clear the other
    end (``split``): {beam row: ring (segments, 3)}, all tested at once; their first vertices
    in the frames of ``linear`` (``split``)."""
    x, y = bn[js, 0], bn[js, 1]
    bound = cut_bound(segments)
    axis = c[y] - c[x]
    length = np.linalg.norm(axis, axis=1)
    scale = tangent_scale(segments)
    rx, ry = rad[x] * scale, rad[y] * scale
    ok = length > np.abs(rx - ry)
    length = np.where(ok, length, 1.0)
    a = axis / length[:, None]
    cos_t = np.where(ok, (rx - ry) / length, 0.0)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    px, py = rx * cos_t, length + ry * cos_t  # the tangent circles' positions along the axis, radii ρ
    rho_x, rho_y = rx * sin_t, ry * sin_t
    lo, hi = np.maximum(px, rad[x] * bound), np.minimum(py, length - rad[y] * bound)
    ok &= hi > lo
    p = 0.5 * (lo + hi)
    rho = rho_x + (rho_y - rho_x) * (p - px) / np.where(py > px, py - px, 1.0)
    # each beam's two sides: the other end's half (its frustum) against `near`'s ball and its other beams
    near = np.concatenate([x, y])
    start, stop = np.concatenate([p, px]), np.concatenate([py, p])
    r_half = np.concatenate([np.maximum(rho, rho_y), np.maximum(rho_x, rho)]) * bound
    a2, cx2 = np.concatenate([a, a]), np.concatenate([c[x], c[x]])
    s0, s1 = cx2 + start[:, None] * a2, cx2 + stop[:, None] * a2
    gap = segment_distance(s0, s1, c[near], c[near])
    clear = gap > rad[near] * bound + r_half + margin
    # the cluster's beams at each near hub, but the beam itself
    ends = bn[beams]
    hub, beam = np.concatenate([ends[:, 0], ends[:, 1]]), np.concatenate([beams, beams])
    order = np.argsort(hub, kind="stable")
    hub, beam = hub[order], beam[order]
    first = np.searchsorted(hub, near)
    count = np.searchsorted(hub, near, "right") - first
    side = np.repeat(np.arange(len(near)), count)
    other = beam[runs(first, count)]
    keep = other != np.concatenate([js, js])[side]
    side, other = side[keep], other[keep]
    o = bn[other]
    reach = np.maximum(rad[o[:, 0]], rad[o[:, 1]]) * bound
    hit = segment_distance(s0[side], s1[side], c[o[:, 0]], c[o[:, 1]]) <= reach + r_half[side] + margin
    clear[side[hit]] = False
    ok &= clear[:len(js)] & clear[len(js):]
    k = np.flatnonzero(ok)
    if not len(k):
        return {}
    e1, e2 = ring_frames(a[k], None if linear is None else linear(js[k]))
    ang = 2 * np.pi * np.arange(segments) / segments
    rings = ((c[x[k]] + p[k, None] * a[k])[:, None] + rho[k, None, None]
             * (np.cos(ang)[None, :, None] * e1[:, None] + np.sin(ang)[None, :, None] * e2[:, None]))
    return dict(zip(js[k].tolist(), rings))


def ring_frames(axes: np.ndarray, linear=None) -> tuple[np.ndarray, np.ndarray]:
    """(e1, e2) (K, 3) orthonormal to unit ``axes`` (K, 3), right-handed: ``perpendicular_frames``
    of each axis seen from its frame (``linear`` (K, 3, 3), a similarity's linear part), carried
    back by it, so that an axis moved by a similarity gets its frame moved too (world axes
    without ``linear``, or where a frame is degenerate)."""
    if linear is None or not len(axes):
        return perpendicular_frames(axes)
    m = np.asarray(linear, float).reshape(-1, 3, 3)
    local = np.linalg.solve(m, axes[:, :, None])[:, :, 0]  # the axis in its group's frame
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    e1 = np.einsum("kab,kb->ka", m, perpendicular_frames(local)[0])
    e1 -= np.einsum("ki,ki->k", e1, axes)[:, None] * axes  # exactly normal to the axis (rounding)
    norm = np.linalg.norm(e1, axis=1)
    world = perpendicular_frames(axes)
    ok = np.isfinite(norm) & (norm > 1e-6 * np.linalg.norm(m.reshape(len(m), -1), axis=1))
    e1 = np.where(ok[:, None], e1 / np.where(ok, norm, 1.0)[:, None], world[0])
    return e1, np.cross(axes, e1)


def excluded(report, beam_nodes) -> tuple[np.ndarray, np.ndarray]:
    """Hub rows (E) and beam rows (B) the clusters of ``report`` mesh: the fast path leaves them out."""
    cl = clusters(report, beam_nodes)
    hubs = np.concatenate([c.hubs for c in cl]) if cl else np.zeros(0, np.int64)
    beams = np.concatenate([c.beams for c in cl]) if cl else np.zeros(0, np.int64)
    return np.sort(hubs), np.sort(beams)


def piece_estimate(cluster: Cluster) -> tuple[int, int]:
    """(input triangles, peak bytes) of a cluster's union, from above: a polygonal ball per hub,
    a hull per beam of at most two balls' vertices (a contact ring has fewer than a ball)."""
    ball = ball_triangles(cluster.segments)
    tris = (len(cluster.hubs) + 2 * len(cluster.beams) + 2 * len(cluster.halves)) * ball
    return tris, tris * UNION_TRIANGLE_BYTES


def ball_triangles(segments: int) -> int:
    """Triangles of a polygonal ball of ``segments`` (from above: manifold3d's sphere)."""
    return 2 * segments * (segments // 2)


def unit_ball(manifold3d, segments: int = SPHERE_SEGMENTS):
    """A polygonal unit sphere (manifold3d) whose volume is the exact ball's (4π/3)."""
    s = manifold3d.Manifold.sphere(1.0, segments)
    k = (4.0 / 3.0 * np.pi / s.volume()) ** (1.0 / 3.0)
    return s.scale([k, k, k])


_UNIT: dict = {}


def _unit_vertices(manifold3d, segments: int = SPHERE_SEGMENTS) -> np.ndarray:
    """The vertices of ``unit_ball`` (computed once per process and segment count)."""
    if segments not in _UNIT:
        _UNIT[segments] = np.asarray(unit_ball(manifold3d, segments).to_mesh64().vert_properties[:, :3], float)
    return _UNIT[segments]


def tangent_scale(segments: int) -> float:
    """The circumradius of a ``segments``-gon whose area is the unit circle's (a cut ring's, so that
    the beam keeps the cross-section of the exact one, as ``unit_ball`` its volume)."""
    return float(np.sqrt(2 * np.pi / (segments * np.sin(2 * np.pi / segments))))


CAP_ROWS = 2  # rows of a ball's vertices beyond the tangent circle that its beams' hulls take in


def beam_points(ends, centers, segments: int = SPHERE_SEGMENTS) -> np.ndarray:
    """Points whose convex hull, with the balls, is a cluster's beam (§3: a beam is the hull of
    its two balls): ``ends`` two items, each a ball's vertices (P, 3) (its centre in ``centers``)
    or a ring (k, 3), told apart by ``centers`` (None for a ring). A ball enters by its cap only:
    the vertices within ``CAP_ROWS`` rows of segments behind the circle where the beam's tangent
    cone touches it. The hull with the whole ball is the ball and that cap's hull, so the union is
    the same, and the fewer vertices the beams of one ball share, the faster the Boolean."""
    pts = [np.asarray(e, float).reshape(-1, 3) for e in ends]
    mids = [np.asarray(c, float) if c is not None else p.mean(axis=0) for p, c in zip(pts, centers)]
    axis = mids[1] - mids[0]
    length = float(np.linalg.norm(axis))
    if length == 0 or all(c is None for c in centers):
        return np.concatenate(pts)
    a = axis / length
    reach = [float(np.linalg.norm(p - m, axis=1).max()) for p, m in zip(pts, mids)]
    out = []
    for e, (p, c) in enumerate(zip(pts, centers)):
        if c is None:
            out.append(p)
            continue
        toward = a if e == 0 else -a
        # the tangent circle of the outer cone of the two ends (each as its bounding sphere)
        cos_t = np.clip((reach[e] - reach[1 - e]) / length, -1.0, 1.0)
        angle = np.arccos(cos_t) + CAP_ROWS * 2 * np.pi / segments
        w = p - mids[e]
        cos_v = (w @ toward) / np.maximum(np.linalg.norm(w, axis=1), 1e-300)
        out.append(p[cos_v >= np.cos(min(angle, np.pi))])
    return np.concatenate(out)


def _turned(points: np.ndarray, turns) -> np.ndarray:
    """Unit-ball vertices turned by Euler angles ``turns`` (fractions of a full turn, (3,))."""
    out = points
    for axis, t in enumerate(turns):
        a = 2 * np.pi * t
        c, s = np.cos(a), np.sin(a)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        out = out @ r.T
    return out


STOPPABLE_TRIANGLES = 200_000  # clusters from this estimate on are united in a child process


def unite_stoppable(cluster: Cluster, center, radius, beam_nodes, rings: dict, grid: float):
    """``unite_cluster``, in a forked child process when the cluster is large
    (``STOPPABLE_TRIANGLES``): a signal then stops the command at once (the child is killed)
    instead of after a long call into manifold3d that holds the interpreter."""
    if piece_estimate(cluster)[0] < STOPPABLE_TRIANGLES:
        return unite_cluster(cluster, center, radius, beam_nodes, rings, grid)
    return stoppable(unite_cluster, cluster, center, radius, beam_nodes, rings, grid)


def stoppable(fn, *args):
    """``fn(*args)`` in a forked child process (where there is fork): a signal stops the command
    at once (the child is killed) instead of after a long call into manifold3d that holds the
    interpreter. A PleError in the child is raised here."""
    if not hasattr(os, "fork"):
        return fn(*args)
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(send, fn, *args), daemon=True)
    child.start()
    send.close()
    try:
        while not recv.poll(0.05):
            if not child.is_alive():
                break
        try:
            ok, value = recv.recv()
        except EOFError:  # it died without a word (killed, out of memory)
            raise PleError("the union of an unclean cluster ended without a result (out of memory?)") from None
    finally:
        if child.is_alive():
            child.kill()
        child.join()
        recv.close()
    if not ok:
        raise value
    return value


def _child(send, fn, *args) -> None:
    try:
        send.send((True, fn(*args)))
    except Exception as exc:  # a PleError, or a bug: raised in the parent as it is
        send.send((False, exc))
    finally:
        send.close()


def manifold3d_module():
    try:
        import manifold3d
    except ImportError as exc:  # pragma: no cover - a runtime dependency of unclean meshing
        raise PleError("meshing an unclean lattice needs manifold3d (pip install manifold3d)") from exc
    return manifold3d


def unite_cluster(cluster: Cluster, center, radius, beam_nodes, rings: dict, grid: float):
    """The mesh of one cluster (vertices (V, 3), faces (F, 3)), open along the rings it shares
    with clean junctions. ``rings``: (beam row, end 0|1) -> ring vertices (k, 3) in world
    coordinates (clockwise about the beam, as the fast path placed them) for each end of the
    cluster's beams that is not one of its hubs. Tries the balls as they are, then each turned
    its own way (identical balls give symmetric lattices coplanar faces that a Boolean may leave
    overlapping): ``TURN_TRIES``, from the second on for a cluster of ``STOPPABLE_TRIANGLES`` or
    more (a thick lattice, whose symmetric beams meet tangentially on balls as they are: a failed
    try costs as much as the union)."""
    manifold3d = manifold3d_module()
    last = None
    for turns in TURN_TRIES[piece_estimate(cluster)[0] >= STOPPABLE_TRIANGLES:]:
        try:
            v, f, keys = _united(manifold3d, cluster, center, radius, beam_nodes, rings, turns)
            centre = v.mean(axis=0) if len(v) else np.zeros(3)
            reach = float(np.linalg.norm(v - centre, axis=1).max()) if len(v) else 0.0
            pinned = [rings[k] for k in keys]
            v, f = on_grid(v, f, grid, centre[None], reach, rings=pinned)
            return open_rings(v, f, pinned, keys)
        except PleError as exc:
            last = exc
    raise last


BATCH_TRIANGLES = 100_000  # input triangles of the small clusters put on the grid and checked at once


def unite_batch(batch: list, center, radius, beam_nodes, rings: list, grid: float) -> list:
    """``unite_cluster`` for many small clusters at once (``batch``, each with its ``rings``, at
    least one): each is united on its own, then all are put on the grid, checked and opened in one
    ``on_grid`` and one ``open_rings`` (their cost is mostly per call), and split again by the
    connected pieces of the result, each found by its ring vertices. Returns a piece per cluster,
    or None for every cluster when anything fails (then each is united alone)."""
    manifold3d = manifold3d_module()
    vs, fs, keys, centres, at = [], [], [], [], 0
    try:
        for k, (c, rg) in enumerate(zip(batch, rings)):
            v, f, ks = _united(manifold3d, c, center, radius, beam_nodes, rg, None)
            if not ks or not len(f):
                return [None] * len(batch)
            vs.append(v)
            fs.append(f + at)
            at += len(v)
            keys += [(k, key) for key in ks]
            centres.append(v.mean(axis=0))
        v, f = np.concatenate(vs), np.concatenate(fs)
        centres = np.asarray(centres)
        reach = max(float(np.linalg.norm(x - y, axis=1).max()) for x, y in zip(vs, centres))
        pinned = [rings[k][key] for k, key in keys]
        v, f = on_grid(v, f, grid, centres, reach, rings=pinned)
        v, f = open_rings(v, f, pinned, keys)
    except PleError:
        return [None] * len(batch)
    label = component_labels(len(v), np.concatenate([f[:, [0, 1]], f[:, [1, 2]]]))
    ids = match_rows(np.concatenate(pinned), v)
    if (ids < 0).any():
        return [None] * len(batch)
    ring_owner = np.repeat([k for k, _ in keys], [len(r) for r in pinned])
    whose = np.full(int(label.max()) + 1, -1, np.int64)  # the cluster of each connected piece
    whose[label[ids]] = ring_owner
    if (whose[label[ids]] != ring_owner).any() or (whose[label[np.unique(f)]] < 0).any():
        return [None] * len(batch)  # a piece without rings, or two clusters in one piece
    out = []
    face_owner = whose[label[f[:, 0]]]  # a cluster's union may be open into several pieces
    for k in range(len(batch)):
        fk = f[face_owner == k]
        used = np.unique(fk)
        remap = np.full(len(v), -1, np.int64)
        remap[used] = np.arange(len(used))
        out.append((v[used], remap[fk]))
    return out


def _united(manifold3d, cluster, center, radius, beam_nodes, rings, turns):
    """The Boolean union of a cluster's balls and beams (manifold3d): (vertices, faces, the keys
    of its rings: those shared with the fast path, and its cut rings)."""
    parts, keys = element_hulls(manifold3d, cluster, center, radius, beam_nodes, rings, turns)
    out = manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add).to_mesh64()
    return np.asarray(out.vert_properties[:, :3], float), np.asarray(out.tri_verts, np.int64), keys


def element_hulls(manifold3d, cluster, center, radius, beam_nodes, rings, turns):
    """A cluster's balls and beams as convex manifold3d solids (hubs first, then beams, then
    halves), and the keys of its rings: those shared with the fast path, and its cut rings."""
    make = Elements(manifold3d, cluster, center, radius, beam_nodes, rings, turns)
    return [make.hull(i) for i in range(make.count)], make.keys


class Elements:
    """A cluster's balls and beams (``element_hulls``' order), each made when asked for: a slab
    (``ple.meshing.slabs``) holds only its own."""

    def __init__(self, manifold3d, cluster, center, radius, beam_nodes, rings, turns):
        self.manifold3d, self.cluster, self.rings, self.turns = manifold3d, cluster, rings, turns
        self.unit = _unit_vertices(manifold3d, cluster.segments)
        if turns == "all":  # every ball by one turn (``TURN_TRIES``)
            self.unit = _turned(self.unit, BALL_TURNS)
        self.c, self.rad = np.asarray(center, float), np.asarray(radius, float)
        self.bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
        self.own = set(cluster.hubs.tolist())
        self.hubs, self.beams = len(cluster.hubs), len(cluster.beams)
        self.count = self.hubs + self.beams + len(cluster.halves)
        # the rings shared with the fast path, and the cut rings shared with the other halves' unions
        self.keys = sorted(k for k in rings if k[1] == CUT or int(self.bn[k[0], k[1]]) not in self.own)

    def ball(self, x: int) -> np.ndarray:
        u = self.unit if self.turns != "each" else _turned(self.unit, np.modf(x * BALL_TURNS)[0])
        return u * self.rad[x] + self.c[x]

    def points(self, i: int) -> np.ndarray:
        """The points whose hull is element i."""
        bn, c, own, rings = self.bn, self.c, self.own, self.rings
        if i < self.hubs:
            return self.ball(int(self.cluster.hubs[i]))
        if i < self.hubs + self.beams:
            j = int(self.cluster.beams[i - self.hubs])
            x = [int(bn[j, e]) for e in (0, 1)]
            return beam_points([self.ball(x[e]) if x[e] in own else rings[(j, e)] for e in (0, 1)],
                               [c[x[e]] if x[e] in own else None for e in (0, 1)], self.cluster.segments)
        j, e = (int(t) for t in self.cluster.halves[i - self.hubs - self.beams])
        x = int(bn[j, e])
        return beam_points([self.ball(x), rings[(j, CUT)]], [c[x], None], self.cluster.segments)

    def hull(self, i: int):
        p = self.manifold3d.Manifold.hull_points(self.points(i))
        if p.status() != self.manifold3d.Error.NoError or p.is_empty():
            raise PleError("a beam of an unclean cluster has no volume (its two ends are flat)")
        return p


def open_rings(v, f, rings: list, keys: list, seams: np.ndarray | None = None):
    """Remove the faces lying on the rings (every corner a vertex of one ring: the ring's
    polygon), and check that what is left is open exactly along each ring's edges
    (``RingTouchedError`` naming the first ring that is not, by its key of ``keys``) and along
    ``seams`` (E, 2: vertex pairs of edges that are open already, a slab's cut planes)."""
    if not rings:
        return v, f
    rings = [np.asarray(r, float).reshape(-1, 3) for r in rings]
    pts = np.concatenate(rings)
    sizes = [len(r) for r in rings]
    ring_of = ring_of_vertices(v, rings)
    f = f[~on_one_ring(f, ring_of)]
    n = max(len(v), 1)
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    d = d[~np.isin(d[:, 0] * n + d[:, 1], d[:, 1] * n + d[:, 0])]  # directed edges without their reverse
    open_edges = np.unique(np.minimum(d[:, 0], d[:, 1]) * n + np.maximum(d[:, 0], d[:, 1]))
    ids = match_rows(pts, v)
    want, touched = [], []
    for key, part in zip(keys, np.split(ids, np.cumsum(sizes)[:-1])):
        nxt = np.roll(part, -1)
        edges = np.minimum(part, nxt) * n + np.maximum(part, nxt)
        if (part < 0).any() or not np.isin(edges, open_edges).all():
            touched.append(key)
        else:
            want.append(edges)
    if touched:
        raise RingTouchedError("a ring of an unclean cluster was changed by its union", touched)
    if seams is not None and len(seams):
        want.append(np.minimum(seams[:, 0], seams[:, 1]) * n + np.maximum(seams[:, 0], seams[:, 1]))
    extra = np.setdiff1d(open_edges, np.concatenate(want)) if want else open_edges
    if len(extra):
        ends = np.concatenate([extra // n, extra % n])
        rows = sorted({int(r) for r in ring_of[ends] if r >= 0})
        raise RingTouchedError("a ring of an unclean cluster was touched by its union",
                               [keys[r] for r in rows] or list(keys))
    return v, f


SHAPE_QUANTUM = 2.0**-10  # grid steps: clusters whose inputs agree to this, relative to an anchor, share a piece
TURNED_QUANTUM = 2.0**-4  # grid steps: the distances that sort turned copies (a candidate is then fitted)
TURNED_FIT = 2.0**-6  # grid steps: how far a turned copy's inputs may lie from the kept shape moved onto them
TURNED_CANDIDATES = 4  # kept shapes tried per distance key
CACHE_TRIANGLES = 1 << 21  # triangles of united pieces kept for copies (the least recently used go first)


@dataclass
class Shape:
    """A cluster's inputs as ``ShapeCache`` sees them: ``key`` (translations), ``like`` (turns)."""

    key: tuple | None
    anchor: np.ndarray | None
    ring_keys: list
    points: np.ndarray  # (N, 3): balls' centres, then ring vertices in the order of ring_keys
    radii: np.ndarray  # (H,): the balls' radii
    like: tuple | None = None


class ShapeCache:
    """United pieces kept by shape, for the copies of a cluster (a steady lattice repeats its
    unclean neighbourhoods: every crossing of a row of diagonals, every hub of one shape).

    A cluster's shape is its inputs (balls of its hubs, the ring vertices of its beams' clean ends,
    in the cluster's row order) relative to an anchor (its first ball's centre, or its first ring
    vertex), quantized to ``SHAPE_QUANTUM`` grid steps. A copy whose anchor lies a whole number of
    grid steps from the cached one takes the cached piece (already on the grid, checked there)
    moved by that exact translation, with its ring vertices replaced by its own: the floats the
    fast path places at that copy, so the seams stay exact.

    Turned copies (rows of a rotation, a screw) are found by the distances of their inputs from
    their centroid (``TURNED_QUANTUM`` grid steps); the kept shape is fitted onto the copy's
    inputs (Kabsch, a proper rotation) and taken when every input lands within ``TURNED_FIT``
    grid steps. Its piece is moved, snapped to the grid, given the copy's ring vertices, and
    checked as ``unclean.on_grid`` leaves a union: no two vertices on one grid point, no faces
    that meet when rounded to twice the grid (exact), no cap flatter than ``COLLAPSE_GRIDS``
    grid steps that the kept piece did not have. A copy that fails is united anew.
    Memory: at most ``CACHE_TRIANGLES`` kept triangles."""

    def __init__(self, grid: float, limit: int = CACHE_TRIANGLES):
        self.grid = float(grid)
        self.limit = limit
        self.kept: dict = {}  # key -> (vertices, faces, anchor, ring ids, shape, flat faces, search cell)
        self.alike: dict = {}  # like -> keys of kept shapes (at most TURNED_CANDIDATES)
        self.triangles = 0
        self.hits = 0
        self.turned = 0

    def shape(self, cluster: Cluster, center, radius, beam_nodes, rings: dict) -> Shape:
        """The shape of a cluster (its keys, anchor, ring keys and inputs)."""
        bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
        hubs = np.sort(np.asarray(cluster.hubs, np.int64))
        order = {h: k for k, h in enumerate(hubs.tolist())}
        beams = sorted(np.asarray(cluster.beams, np.int64).tolist())
        halves = sorted(map(tuple, np.asarray(cluster.halves, np.int64).reshape(-1, 2).tolist()))
        ring_keys, ends = [], []  # the rings of its beams' clean ends, then its cut rings; each end's hub
        for j, pair in zip(beams, bn[beams].tolist()):
            for e in (0, 1):
                ends.append(order.get(pair[e], -1))
                if ends[-1] < 0:
                    ring_keys.append((j, e))
        for j, e in halves:
            ring_keys.append((j, CUT))
            ends.append(order[int(bn[j, e])])
        pts = [np.asarray(rings[k], float).reshape(-1, 3) for k in ring_keys]
        if len(hubs):
            pts.insert(0, np.asarray(center, float)[hubs])
        pts = np.concatenate(pts) if pts else np.zeros((0, 3))
        rad = np.asarray(radius, float)[hubs]
        if not len(pts):
            return Shape(None, None, ring_keys, pts, rad)
        anchor = pts[0]
        sizes = np.array([len(hubs), len(halves), *(len(rings[k]) for k in ring_keys), *ends], np.int64).tobytes()
        body = (pts - anchor).ravel()
        if len(rad):
            body = np.concatenate([body, rad])
        body = np.round(body * (1.0 / (self.grid * SHAPE_QUANTUM)))
        return Shape((sizes, body.tobytes()), anchor, ring_keys, pts, rad)

    def like(self, shape: Shape) -> tuple | None:
        """The key of a shape's turned copies (the distances of its inputs from their centroid),
        computed once, when its translations are not kept."""
        if shape.like is None and shape.key is not None:
            d = shape.points - shape.points.sum(axis=0) * (1.0 / len(shape.points))
            spread = np.round(np.concatenate([np.sqrt(np.einsum("ij,ij->i", d, d)), shape.radii])
                              * (1.0 / (self.grid * TURNED_QUANTUM)))
            shape.like = (shape.key[0], spread.tobytes())
        return shape.like

    def get(self, shape: Shape, rings: dict):
        """The piece of a copy of a kept shape, or None."""
        if shape.key is None:
            return None
        hit = self.kept.get(shape.key)
        if hit is not None:
            v0, f, at, ids = hit[:4]
            d = shape.anchor - at
            step = np.round(d / self.grid) * self.grid
            if np.max(np.abs(d - step)) <= self.grid * SHAPE_QUANTUM:
                self.kept[shape.key] = self.kept.pop(shape.key)  # most recently used
                v = v0 + step
                for k, r in zip(shape.ring_keys, ids):
                    v[r] = rings[k]
                self.hits += 1
                return v, f  # (read-only: shared by the copies)
        for key in self.alike.get(self.like(shape), ()):
            kept = self.kept.get(key)  # (or gone: the least recently used)
            piece = None if kept is None else self._moved(kept, shape, rings)
            if piece is not None:
                self.hits += 1
                self.turned += 1
                return piece
        return None

    def _moved(self, kept, shape: Shape, rings: dict):
        """The kept piece moved onto a turned copy (class docstring), or None."""
        v0, f, _, ids, was, flat0, cell = kept
        if len(was.points) != len(shape.points) or np.max(np.abs(was.radii - shape.radii), initial=0.0) > (
                self.grid * TURNED_FIT):
            return None
        rot, t = rigid_fit(was.points, shape.points)
        if rot is None or np.max(np.abs(was.points @ rot.T + t - shape.points)) > self.grid * TURNED_FIT:
            return None
        v = snap(v0 @ rot.T + t, self.grid)
        for k, r in zip(shape.ring_keys, ids):
            v[r] = rings[k]
        on = snap(v, self.grid)
        t3 = on[f]
        if not (t3 != t3[:, [1, 2, 0]]).any(axis=2).all():
            return None  # an edge's two ends on one grid point (other vertices that meet are met below)
        flat = flat_faces(v, f, self.grid)
        if not np.isin(flat, flat0).all():
            return None
        if len(self_intersections(snap(v, 2 * self.grid), f, cell=cell)):
            return None
        self._keep(shape, v, f, ids, flat, cell)  # the translations of this copy are then found directly
        return v, f

    def put(self, shape: Shape, rings: dict, piece) -> None:
        if shape.key is None or shape.key in self.kept:
            return
        v, f = piece
        pts = [np.asarray(rings[k], float).reshape(-1, 3) for k in shape.ring_keys]
        at = match_rows(np.concatenate(pts), v) if pts else np.zeros(0, np.int64)
        if (at < 0).any():  # a ring vertex not in the piece (not for an opened piece): not kept
            return
        ids = np.split(at, np.cumsum([len(p) for p in pts])[:-1])
        self._keep(shape, np.asarray(v, float), np.asarray(f, np.int64), ids)

    def _keep(self, shape: Shape, v, f, ids, flat=None, cell=None) -> None:
        f = np.asarray(f, np.int64)
        f.flags.writeable = False  # the copies' pieces share it (and the piece it came with)
        if shape.key in self.kept:  # a copy of this shape off the whole grid steps: it takes its place
            self.triangles -= len(self.kept.pop(shape.key)[1])
        self.kept[shape.key] = (v, f, np.asarray(shape.anchor, float), ids, shape,
                                flat_faces(v, f, self.grid) if flat is None else flat,
                                search_cell(v, f) if cell is None else cell)
        alike = self.alike.setdefault(self.like(shape), [])
        alike.insert(0, shape.key)
        del alike[TURNED_CANDIDATES:]
        self.triangles += len(f)
        while self.triangles > self.limit and len(self.kept) > 1:
            oldest = next(iter(self.kept))
            self.triangles -= len(self.kept.pop(oldest)[1])


def rigid_fit(p: np.ndarray, q: np.ndarray):
    """The proper rotation R (3, 3) and translation t (3,) that best move the points p (N, 3) onto
    q (N, 3) (least squares, Kabsch); (None, None) when the best orthogonal map is a reflection."""
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    u, _, vt = np.linalg.svd((p - pc).T @ (q - qc))
    rot = (u @ vt).T
    if np.linalg.det(rot) < 0:
        if len(p) > 3 and np.linalg.matrix_rank(p - pc, tol=1e-9 * max(1.0, float(np.abs(p - pc).max()))) == 3:
            return None, None
        rot = (u @ np.diag([1.0, 1.0, -1.0]) @ vt).T  # flat inputs: the proper rotation fits as well
    return rot, qc - pc @ rot.T


def flat_faces(v: np.ndarray, f: np.ndarray, grid: float) -> np.ndarray:
    """The faces (ids) whose altitude on their longest edge is under ``COLLAPSE_GRIDS`` grid steps
    (``unclean.on_grid`` collapses such caps)."""
    t = v[f]
    a, b, c = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0], t[:, 2] - t[:, 1]
    n = np.stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                  a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]], axis=1)
    longest = np.maximum(np.maximum(np.einsum("ij,ij->i", a, a), np.einsum("ij,ij->i", b, b)),
                         np.einsum("ij,ij->i", c, c))
    return np.flatnonzero(np.einsum("ij,ij->i", n, n) < (COLLAPSE_GRIDS * grid) ** 2 * longest)
