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

import ctypes
import itertools
import math
import mmap
import multiprocessing
import os
import signal
import threading
import weakref
from collections import deque
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np

from ..algebra.vectors import perpendicular_frames, runs, unit_rows
from ..errors import PleError, echo
from ..model.budget import hub_triangles, mean_degree, region_beams, region_nodes
from ..model.lattice import Lattice, Region
from ..queries.overlaps import grid_pairs
from . import slabs
from .achocc import JunctionError
from .assembly import Packed, Pieces, TemplateTable, fill, hub_faces, place
from .hubs import hub_templates
from .preview import balls_beams_mesh
from .selfcheck import self_intersections
from .skin import clip_bodies, clip_to_bodies
from .slabs import unite_in_slabs_stoppable
from .styles import DEFAULT_LEVELS, DEFAULT_SEGMENTS
from .styles import style as style_named
from .unclean import SEPARATION_GRIDS, ball_segments, component_labels, find_unclean
from .unions import (
    BATCH_TRIANGLES,
    CUT,
    Cluster,
    RingTouchedError,
    ShapeCache,
    clusters,
    piece_estimate,
    split,
    unite_batch,
    unite_stoppable,
)
from .weld import COLLAPSE_GRIDS, grid_spacing, weld

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh

KEY_QUANTUM = 1e-9  # neighbourhoods equal to this fraction of the ball radius share a hub mesh
MAX_LEVELS = 6
PLACED_VERTICES = 1 << 20  # template vertices the unclean check places at once (24 MiB)
HULL_VERTICES = 64  # hub templates up to this many vertices are their own hull points (``_hull_ids``)
STEADY_MIN_LAYERS = 6  # the unclean check looks up anchors and border layers only from this many inner layers on
MAX_CHECK_GROUPS = 500_000  # streamed regions up to this size are checked for unclean hubs first
CHECK_ELEMENT_BYTES = 340  # peak bytes of that check per hub and beam, evaluation and start-up in (measured 230-310)
BOX_TRIANGLES = 1 << 22  # triangles of a streamed box, at most (about: the estimate is from above)
TEMPLATE_CHUNK = 768  # hub shapes per template task (fixed: the output must not depend on the workers)
POOL_MAP_MIN = 1 << 20  # pooled buffers from this size on are mapped in small pages (``fresh_buffer``)
POOL_HEADROOM = 0.125  # a fresh pooled buffer's room beyond the size asked for (fraction)
TEMPLATE_SPLIT = 128  # a beam set's new hub shapes from this many on are built in an even number of tasks
TEMPLATE_ROUND = 4  # streamed boxes whose new hub shapes are built together (fixed, as TEMPLATE_CHUNK)


class ArrayPool:
    """Memory of streamed boxes handed from encoded boxes to the next ones (thread-safe): a
    box's vertices and faces are fresh arrays of some 100 MB, and first touches of fresh pages
    cost as much as assembling them (seconds of system time over a large stream here). At most
    as many buffers as arrays alive at once, each as large as the largest asked for so far plus
    ``POOL_HEADROOM`` (boxes of a stream differ by a few per cent: without it, every slightly
    larger box replaced a buffer by a fresh one, a third of the fresh memory of a curved stream).
    Fresh buffers are mapped in small pages (``fresh_buffer``)."""

    def __init__(self):
        self._free: list = []
        self._lock = threading.Lock()

    def take(self, shape: tuple, dtype) -> np.ndarray:
        """An uninitialised array (a view of a reused buffer when one is large enough)."""
        dtype = np.dtype(dtype)
        size = int(np.prod(shape)) * dtype.itemsize
        with self._lock:  # the smallest that fits, else the largest (replaced by a larger one)
            order = sorted(range(len(self._free)), key=lambda i: len(self._free[i]))
            fit = next((i for i in order if len(self._free[i]) >= size), order[-1] if order else None)
            buf = self._free.pop(fit) if fit is not None else None
        if buf is None or len(buf) < size:  # too small: dropped, a larger one takes its place
            buf = fresh_buffer(max(size + int(size * POOL_HEADROOM), 1))
        return buf[:size].view(dtype).reshape(shape)

    def give(self, *arrays) -> None:
        """Hand back arrays from ``take`` (others are ignored) once nothing reads them."""
        for a in arrays:
            buf = a.base if isinstance(a, np.ndarray) else None
            while isinstance(buf, np.ndarray) and isinstance(buf.base, np.ndarray):
                buf = buf.base  # to the buffer (whose own base may be its memory map)
            if isinstance(buf, np.ndarray) and buf.dtype == np.uint8 and buf.ndim == 1:
                with self._lock:
                    self._free.append(buf)


def fresh_buffer(size: int) -> np.ndarray:
    """``size`` uninitialised bytes for a pooled buffer: a private anonymous map advised against
    transparent huge pages where the platform has them (else ``np.empty``). First touches of
    huge pages took 0.09 to 2 s per GB on this VM (whether the host had backed them yet), of 4 KiB
    pages a steady 0.4 s: curved 40³ refined, 1.6 GB of pooled buffers, main-process system time
    3.0 -> 1.0 s. Unmapped once no array uses it."""
    if size < POOL_MAP_MIN or not all(hasattr(mmap, k) for k in ("MAP_PRIVATE", "MAP_ANONYMOUS", "MADV_NOHUGEPAGE")):
        return np.empty(size, np.uint8)
    mm = mmap.mmap(-1, size, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    try:
        mm.madvise(mmap.MADV_NOHUGEPAGE)
    except OSError:  # not supported here: huge pages it is
        pass
    return np.frombuffer(mm, np.uint8)


def _task_bounds(n: int) -> list:
    """Template tasks of a beam set's n new hub shapes: at most TEMPLATE_CHUNK each and, from
    TEMPLATE_SPLIT on, an even number of near-equal ones (a beam set's hubs on two processes
    end together; three tasks of 456 hubs left one process alone with the last for a third of
    each curved round). Fixed by n only: the output does not depend on the workers."""
    k = -(-n // TEMPLATE_CHUNK)
    if n >= TEMPLATE_SPLIT:
        k += k % 2
    cuts = [n * i // k for i in range(k + 1)] if k else [0]
    return [(lo, hi) for lo, hi in zip(cuts[:-1], cuts[1:]) if hi > lo]


def _hub_templates_task(args):
    """``hub_templates`` of args (the last: the beam set's representatives so far), in a template
    process (``Tessellator.pool``) or not. Returns (templates packed for the template table,
    hint, representatives)."""
    *args, reps = args
    reps = list(reps)
    tpls, hint = hub_templates(*args, reps=reps)
    return Packed(tpls), hint, reps


def _template_process_init() -> None:
    """A template process dies with the process that forked it (a SIGTERM, a SIGKILL or a crash of
    the command leaves no orphan behind), holds none of its output streams (a caller reading the
    command's stdout to its end is not kept waiting), and leaves signals to its parent. Its
    allocator keeps freed memory for the next templates (``_keep_freed_memory``)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1 (Linux)
    except (OSError, AttributeError):
        pass
    _keep_freed_memory()
    if os.getppid() == 1:  # the parent is gone already
        os._exit(0)
    devnull = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(devnull, fd)
    os.close(devnull)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


def _keep_freed_memory() -> None:
    """glibc's malloc in a template process: arrays up to 32 MB from the heap, never trimmed
    (its peak stays its size), so each template round reuses the pages of the last instead
    of mapping fresh ones — first touches were two thirds of these processes' system time here
    (160 k page faults in a curved 40³ stream). Not done in the caller's process (a library,
    maybe Blender). Elsewhere (no glibc) nothing changes."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD: the largest value glibc takes on 64-bit
    mallopt(-1, 1 << 30)  # M_TRIM_THRESHOLD
    mallopt(-2, 64 << 20)  # M_TOP_PAD: the heap grows in large steps


def zipper(angles_a: np.ndarray, angles_b: np.ndarray) -> np.ndarray:
    """Strip between two closed rings listed counter-clockwise about the beam axis, ring A at
    the near end, B at the far end, with angles (radians) about the axis.

    Returns faces (ma + mb, 3, 2) of (ring, index) pairs, ring 0 = A, 1 = B, oriented with
    outward normals: the beam traverses A counter-clockwise and B clockwise (the reverse of
    the hubs' rings), so the strip and the hubs close up (§6: a triangle strip choosing the
    next sample on one ring or the other by angle). ``zippers`` for K strips at once."""
    return zippers(np.asarray(angles_a)[None], np.asarray(angles_b)[None])[0]


def zippers(angles_a: np.ndarray, angles_b: np.ndarray) -> np.ndarray:
    """``zipper`` of K strips whose rings have the same sizes: angles (K, ma) and (K, mb);
    faces (K, ma + mb, 3, 2)."""
    k, ma = angles_a.shape
    mb = angles_b.shape[1]
    two_pi = 2 * np.pi
    rows = np.arange(k)[:, None]
    pa = _unwrap_ring(angles_a)
    rel = (angles_b - angles_a[:, :1] + np.pi) % two_pi - np.pi
    b0 = np.argmin(np.round(np.abs(rel), 9), axis=1)
    order_b = (np.arange(mb) + b0[:, None]) % mb
    rel0 = rel[np.arange(k), b0][:, None]
    pb = rel0 + _unwrap_ring(angles_b[rows, order_b])
    key_a = np.concatenate([pa[:, 1:], np.full((k, 1), two_pi)], axis=1)  # a-event s (1..ma): reach A[s]
    key_b = np.concatenate([pb[:, 1:], rel0 + two_pi], axis=1)
    keys = np.round(np.concatenate([key_a, key_b], axis=1), 9)  # equal angles (symmetric rings) tie robustly
    is_b = np.broadcast_to(np.concatenate([np.zeros(ma, bool), np.ones(mb, bool)]), keys.shape)
    order = np.lexsort((is_b, keys), axis=-1)
    is_b = is_b[rows, order]
    seen_b = np.cumsum(is_b, axis=1) - is_b  # b-events before each event
    seen_a = np.cumsum(~is_b, axis=1) - ~is_b
    # a-event s: (A[s-1], A[s], B[seen_b]); b-event t: (B[t], B[t-1], A[seen_a])
    sa, tb = seen_a + 1, seen_b + 1
    ring = np.where(is_b[..., None], [1, 1, 0], [0, 0, 1])
    ia = np.stack([(sa - 1) % ma, sa % ma, order_b[rows, seen_b % mb]], axis=-1)
    ib = np.stack([order_b[rows, tb % mb], order_b[rows, (tb - 1) % mb], seen_a % ma], axis=-1)
    return np.stack([ring, np.where(is_b[..., None], ib, ia)], axis=-1).astype(np.int64)


class Tessellator:
    """Builds region meshes box by box, caching hub templates and beam strips."""

    def __init__(self, lat: Lattice, region: Region, style: str, levels: int, segments: int,
                 fillet: float | None = None, batched: bool = True, grid: float | None = None, workers: int = 1):
        lat.validate()
        self.fillet = fillet
        self.batched = batched  # hub templates in batches of one CHoCC topology (False: one by one)
        self.lat, self.region, self.style, self.levels, self.segments = lat, region, style, levels, segments
        nn = len(lat.nodes)
        # slots of template node n: (pattern, +1 outgoing | -1 incoming)
        self.slots = [[(p, 1) for p, b in enumerate(lat.beams) if b.n1 == n]
                      + [(p, -1) for p, b in enumerate(lat.beams) if b.n2 == n] for n in range(nn)]
        # each beam-pattern's slot at its source node and at its target node
        self.beam_slots = np.array([[self.slots[b.n1].index((p, 1)), self.slots[b.n2].index((p, -1))]
                                    for p, b in enumerate(lat.beams)], np.int64).reshape(-1, 2)
        self.templates: dict = {}
        self.tpl_list: list = []  # (template, slot map) by template id; only appended to
        self.template_nodes: list = []  # the template node of each template id
        self.table = TemplateTable()  # their vertices and faces, for box assembly
        self.strips: dict = {}
        self.hints: dict = {}
        self.reps: dict = {}  # beam set -> representatives of its last template task (``hubs.Rep``)
        self.scale = lat.template_radii * KEY_QUANTUM
        # float32-safe output: edges shorter than a few float32 grid steps of the region's size
        # are collapsed in the hub templates (template units: divided by the smallest group scale)
        self.grid = output_grid(lat, region) if grid is None else grid
        corners = np.array([[i, j, k] for i in (region.i0, max(region.i1 - 1, region.i0))
                            for j in (region.j0, max(region.j1 - 1, region.j0))
                            for k in (region.k0, max(region.k1 - 1, region.k0))])
        fmin = float(np.min(lat.group_factors(corners[:, 0], corners[:, 1], corners[:, 2])))
        self.min_edge = COLLAPSE_GRIDS * self.grid / fmin
        self.hulls: dict = {}  # template id -> ids of its vertices on their convex hull
        # vertex-id lists of templates (hull, or the ring at a slot), flattened (``_vertex_lists``)
        self.id_lists = np.zeros(0, np.int64)
        self.list_at = np.zeros(0, np.int64)
        self.list_size = np.zeros(0, np.int64)
        self.excluded = None  # sorted linear keys of nodes meshed elsewhere (``ple.meshing.unions``)
        self.excluded_beams = None  # sorted keys (source node key · patterns + pattern) of beams meshed elsewhere
        # hub templates of a box are built by ``workers`` processes (the CHoCC per topology is Python
        # work that threads cannot share); forked here, before any thread of the stream starts
        self.pool = None
        if workers > 1 and fillet is None and hasattr(os, "fork"):
            self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("fork"),
                                            initializer=_template_process_init)
            list(self.pool.map(int, range(workers)))  # start them now
            weakref.finalize(self, self.pool.shutdown, wait=False)

    def close_pool(self) -> None:
        """Stop the template processes (the templates built stay)."""
        if self.pool is not None:
            self.pool.shutdown()
            self.pool = None

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

    def beam_excluded(self, src: np.ndarray, pattern: int) -> np.ndarray:
        """Which beams of ``pattern`` from the nodes src (..., 4) a local union meshes
        (``ple.meshing.unions``): their rings stay open (no cap, no strip)."""
        if self.excluded_beams is None or src.size == 0:
            return np.zeros(src.shape[:-1], bool)
        return np.isin(self._key(src) * len(self.lat.beams) + pattern, self.excluded_beams)

    def exclude(self, idx: np.ndarray, beam_index: np.ndarray) -> None:
        """Leave the hubs idx (N, 4) and the beams beam_index (M, 4: source node i, j, k and
        pattern; the source's template node is the pattern's) to local unions."""
        self.excluded = np.unique(self._key(np.asarray(idx, np.int64).reshape(-1, 4)))
        bi = np.asarray(beam_index, np.int64).reshape(-1, 4)
        src = np.concatenate([bi[:, :3], np.array([self.lat.beams[p].n1 for p in bi[:, 3]], np.int64)
                              .reshape(-1, 1)], axis=1)
        self.excluded_beams = np.unique(self._key(src) * len(self.lat.beams) + bi[:, 3])

    def exclude_more(self, idx: np.ndarray, beam_index: np.ndarray) -> None:
        """``exclude`` these hubs and beams too (a cluster that grew)."""
        old_nodes, old_beams = self.excluded, self.excluded_beams
        self.exclude(idx, beam_index)
        if old_nodes is not None:
            self.excluded = np.union1d(self.excluded, old_nodes)
            self.excluded_beams = np.union1d(self.excluded_beams, old_beams)

    def find_unclean(self):
        """The region's unclean hubs (``ple.meshing.unclean.find_unclean``) with r⁺ and the ACHoCC's
        clean flag of every hub from its template. Returns (report, evaluation)."""
        ev = self.lat.evaluate(self.region)
        idx = np.asarray(ev.node_index, np.int64)
        if len(idx) == 0:
            return find_unclean(np.zeros((0, 3)), np.zeros(0), np.zeros((0, 2)), np.zeros(0)), ev
        tids, m = self.instances(idx)[:2]  # not the neighbourhoods (0.4 GB at 10⁶ hubs), held while the check runs
        rp_t = np.array([t.geometry.r_plus for t, _ in self.tpl_list])
        clean_t = np.array([bool(t.geometry.clean) for t, _ in self.tpl_list])
        pulled_t = np.array([bool(t.geometry.pulled) for t, _ in self.tpl_list])
        f = self.lat.group_factors(idx[:, 0], idx[:, 1], idx[:, 2])
        points = partial(self._element_points, idx, tids, m, np.asarray(ev.beam_nodes, np.int64),
                         np.asarray(ev.beam_index, np.int64)[:, 3])
        # hulls more than the largest rounding of two vertices apart (the grid, then twice the grid
        # for files in other units) stay apart in every file
        bn = np.asarray(ev.beam_nodes, np.int64).reshape(-1, 2)
        slots = self.beam_slots[np.asarray(ev.beam_index, np.int64)[:, 3]]
        ordered = self._rings_in_order()
        twisted = ~(ordered[tids[bn[:, 0]], slots[:, 0]] & ordered[tids[bn[:, 1]], slots[:, 1]]) if len(bn) else None
        return find_unclean(ev.center, ev.radius, ev.beam_nodes, rp_t[tids] * f, ~clean_t[tids], points,
                            SEPARATION_GRIDS * self.grid, self._steady_layers(idx), pulled_t[tids],
                            partial(self._hubs_meet, tids, m), twisted, partial(self._hubs_farther, tids, m)), ev

    def _rings_in_order(self) -> np.ndarray:
        """(templates, slots) bool: whether each contact ring of each hub template runs in one
        angular direction about its beam (the axis from the ball's centre through the ring's
        centroid). A beam strip zips its two rings by angle (``zippers``); a ring out of order
        (a vertex behind its predecessor) would fold the strip, so its beams go to unions."""
        width = max((len(x) for x in self.slots), default=0)
        out = np.ones((len(self.tpl_list), max(width, 1)), bool)
        by_size: dict = {}  # ring length -> [(template, slot, ring points)]
        centers = self.lat.template_centers
        for t, (tpl, slot_of) in enumerate(self.tpl_list):
            c = centers[self.template_nodes[t]]
            for s, r in enumerate(slot_of):
                if r >= 0 and len(tpl.rings[r]) >= 3:
                    by_size.setdefault(len(tpl.rings[r]), []).append((t, s, tpl.vertices[tpl.rings[r]] - c))
        for rows in by_size.values():
            t, s, w = zip(*rows)
            w = np.stack(w)
            axis = w.mean(axis=1)
            norm = np.linalg.norm(axis, axis=1)
            e1, e2 = perpendicular_frames(axis / np.where(norm > 0, norm, 1.0)[:, None])
            ang = np.arctan2(np.einsum("gki,gi->gk", w, e2), np.einsum("gki,gi->gk", w, e1))
            step = np.angle(np.exp(1j * (np.roll(ang, -1, axis=1) - ang)))  # each step, closing one included
            out[np.array(t), np.array(s)] = (norm > 0) & ((step > 0).all(axis=1) | (step < 0).all(axis=1))
        return out

    def _steady_layers(self, idx: np.ndarray):
        """``find_unclean``'s ``steady`` (node_index, a, b, shrink) when the region's layers along W
        are similar copies: no filter, no graded radii, no group map (W is the last similarity
        applied, so one similarity maps every group of layer k onto layer k + 1, §6.1.4); hubs
        within the beams' reach along k of the lattice's ends have other beams (other templates).
        None when there are too few inner layers to gain from it."""
        lat, r = self.lat, self.region
        if lat.filter is not None or lat.radius_field is not None or lat.group_map is not None or not len(idx):
            return None
        reach = max([abs(b.dk) for b in lat.beams], default=0)
        a, b = max(r.k0, reach), min(r.k1, lat.counts[2] - reach)
        if b - a < STEADY_MIN_LAYERS:
            return None
        f = lat.group_factors(np.full(b - a, r.i0), np.full(b - a, r.j0), np.arange(a, b))
        return idx, a, b, float(np.min(f) / f[0])

    def _hull_ids(self, t: int) -> np.ndarray:
        """Vertex ids of template t whose convex hull is its vertices' hull: those on it (qhull),
        or all of them for a small template (up to HULL_VERTICES: most are on it, and qhull costs
        more than the extra points) or a flat one (qhull cannot say)."""
        if t not in self.hulls:
            from scipy.spatial import ConvexHull, QhullError  # noqa: PLC0415 - optional package

            v = self.tpl_list[t][0].vertices
            if len(v) <= HULL_VERTICES:
                self.hulls[t] = np.arange(len(v))
                return self.hulls[t]
            try:
                self.hulls[t] = np.asarray(ConvexHull(v).vertices, np.int64)
            except (QhullError, ValueError):
                self.hulls[t] = np.arange(len(v))
        return self.hulls[t]

    def _element_points(self, idx, tids, m, beam_nodes, pattern, elements) -> np.ndarray:
        """Vertices (K, P, 3) whose convex hulls hold the meshes of ``elements`` (rows of the
        region's nodes, then N + rows of its beams; ``find_unclean``'s numbering): a hub's
        template hull vertices, a beam's two contact rings, placed by their hubs' similarities
        as the boxes place them (``assembly.place``). Rows shorter than P repeat their last point
        (the hull is unchanged)."""
        n = len(idx)
        e = np.asarray(elements, np.int64)
        beam = e >= n
        b = e[beam] - n
        # segments (element k, hub row, vertex list): a hub's hull, or a beam's ring at either end
        k = np.concatenate([np.flatnonzero(~beam), np.flatnonzero(beam), np.flatnonzero(beam)])
        hub = np.concatenate([e[~beam], beam_nodes[b, 0], beam_nodes[b, 1]])
        slot = np.concatenate([np.full(int((~beam).sum()), -1), self.beam_slots[pattern[b], 0],
                               self.beam_slots[pattern[b], 1]])
        second = np.repeat([False, False, True], [int((~beam).sum()), len(b), len(b)])
        first_id, size = self._vertex_lists(tids[hub], slot)
        length = np.zeros(len(e), np.int64)
        length[k[~second]] = size[~second]
        offset = np.where(second, length[k], 0)
        np.add.at(length, k[second], size[second])
        out = np.empty((len(e), int(length.max(initial=1)), 3))
        rows, pos = np.unique(hub, return_inverse=True)
        pos = pos.reshape(-1)
        counts = self.table.snapshot()[2][tids[rows], 2]
        group = np.cumsum(counts) // PLACED_VERTICES  # whole templates placed, a bounded number at a time
        for g in np.unique(group).tolist():
            sel = np.flatnonzero(group[pos] == g)
            verts, start = self._placed_hubs(tids, m, rows[group == g])
            at = np.searchsorted(np.flatnonzero(group == g), pos[sel])
            sz = size[sel]
            j = np.arange(int(sz.sum())) - np.repeat(np.cumsum(sz) - sz, sz)
            src = np.repeat(start[at], sz) + self.id_lists[np.repeat(first_id[sel], sz) + j]
            out[np.repeat(k[sel], sz), np.repeat(offset[sel], sz) + j] = verts[src]
        last = np.minimum(np.arange(out.shape[1]), np.maximum(length, 1)[:, None] - 1)
        return np.take_along_axis(out, last[..., None], axis=1)

    def _placed_hubs(self, tids, m, rows) -> tuple[np.ndarray, np.ndarray]:
        """Every vertex of the hubs ``rows`` placed as the boxes place them (``assembly.place``):
        (vertices (V, 3), first vertex of each row (R,))."""
        table = self.table.snapshot()
        counts = table[2][tids[rows], 2]
        start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        verts = np.empty((int(counts.sum()), 3))
        place(table, tids[rows], start, m[rows], verts)
        return verts, start

    def _vertex_lists(self, t: np.ndarray, slot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the vertex ids of template t (S,) at ring slot (S,) (-1: the template's hull
        vertices) start in ``self.id_lists``, and how many there are: (start (S,), size (S,))."""
        width = max((len(x) for x in self.slots), default=0) + 1
        code = t * width + slot + 1
        if len(self.list_at) <= code.max(initial=-1):
            grown = np.full(2 * int(code.max()) + 2, -1, np.int64)
            grown[:len(self.list_at)] = self.list_at
            self.list_at, self.list_size = grown, np.resize(self.list_size, len(grown))
        new = np.unique(code[self.list_at[code] < 0])
        if len(new):
            lists = []
            for c in new.tolist():
                tt, s = divmod(c, width)
                tpl, slot_of = self.tpl_list[tt]
                lists.append(self._hull_ids(tt) if s == 0 else np.asarray(tpl.rings[slot_of[s - 1]], np.int64))
            sizes = np.array([len(x) for x in lists], np.int64)
            self.list_at[new] = len(self.id_lists) + np.cumsum(sizes) - sizes
            self.list_size[new] = sizes
            self.id_lists = np.concatenate([self.id_lists, *lists])
        return self.list_at[code], self.list_size[code]

    def _hubs_meet(self, tids, m, pairs, chunk: int = 2048) -> np.ndarray:
        """Which hub pairs (P, 2 rows) have meshes that meet where the file holds them: each hub's
        faces placed by its similarity and rounded to the output grid, the faces of one within the
        other's bounding box tested exactly (``selfcheck.self_intersections``: a shared point counts
        as meeting). Many pairs are tested at once, each pair moved apart from the others by a
        whole power of two of grid steps (exact in float64)."""
        g = self.grid
        out = np.zeros(len(pairs), bool)
        for lo in range(0, len(pairs), chunk):
            pos, verts, vstart, owner, local = self._pair_faces(tids, m, pairs[lo:lo + chunk])
            verts = np.round(verts / g)  # grid steps, whole numbers
            vcount = np.diff(np.append(vstart, len(verts)))
            box_lo, box_hi = np.minimum.reduceat(verts, vstart), np.maximum.reduceat(verts, vstart)
            # the faces of each side's hub near the other's box
            side, other = pos.reshape(-1), pos[:, ::-1].reshape(-1)
            # faces not wholly behind the other hub along the line from this one's box centre to
            # the other's (every point of the other hub lies at least as far along it) ...
            u = (box_lo[other] + box_hi[other] - box_lo[side] - box_hi[side]) * 0.5
            ahead = np.minimum.reduceat(np.einsum("ij,ij->i", verts[runs(vstart[other], vcount[other])],
                                                  np.repeat(u, vcount[other], axis=0)),
                                        np.cumsum(vcount[other]) - vcount[other])
            along = np.einsum("ij,ij->i", verts[runs(vstart[side], vcount[side])], np.repeat(u, vcount[side], axis=0))
            at = (np.cumsum(vcount[side]) - vcount[side])[owner][:, None] + local
            along = along[at]
            near = np.flatnonzero(np.maximum(np.maximum(along[:, 0], along[:, 1]), along[:, 2])
                                  >= ahead[owner])  # exact: whole numbers
            # ... and within its box
            tri = verts[vstart[side][owner[near]][:, None] + local[near]]
            a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
            whose = other[owner[near]]
            up = np.maximum(np.maximum(a, b), c) >= box_lo[whose] - 1
            down = np.minimum(np.minimum(a, b), c) <= box_hi[whose] + 1
            near = near[up[:, 0] & up[:, 1] & up[:, 2] & down[:, 0] & down[:, 1] & down[:, 2]]
            if not len(near):
                continue
            # every (pair, side) with a near face takes its hub's vertices, its pair moved along x
            # by a whole power of two of grid steps beyond the chunk's largest pair
            span = float((np.maximum(box_hi[pos[:, 0]], box_hi[pos[:, 1]])
                          - np.minimum(box_lo[pos[:, 0]], box_lo[pos[:, 1]])).max())
            step = 2.0 ** math.ceil(math.log2(span + 4.0))
            nv = np.zeros(len(side), np.int64)
            nv[owner[near]] = vcount[side[owner[near]]]
            vbase = np.cumsum(nv) - nv
            v = verts[runs(vstart[side], nv)]
            v[:, 0] += (np.repeat(np.arange(len(side)), nv) // 2) * step
            o = owner[near]
            hits = self_intersections(v, local[near] + vbase[o][:, None], workers=1, sides=o % 2 == 1)
            oa, ob = o[hits[:, 0]], o[hits[:, 1]]
            out[lo + oa[oa // 2 == ob // 2] // 2] = True  # (pairs are far apart: the two sides of one)
        return out

    def _pair_faces(self, tids, m, part):
        """The hubs of pairs ``part`` (P, 2 rows) placed once each: (their rows' places (P, 2) in
        the placed hubs, vertices (V, 3), first vertex of each placed hub, and each face of every
        (pair k, side) as 2k + side: its owner (F,) and vertex ids in its hub (F, 3))."""
        rows, pos = np.unique(np.asarray(part, np.int64), return_inverse=True)
        pos = pos.reshape(-1, 2)
        verts, vstart = self._placed_hubs(tids, m, rows)
        tpl, tpos = np.unique(tids[rows], return_inverse=True)
        tf = [np.asarray(self.tpl_list[t][0].faces, np.int64) for t in tpl.tolist()]
        sizes = np.array([len(f) for f in tf], np.int64)
        nf = sizes[tpos][pos.reshape(-1)]
        owner = np.repeat(np.arange(2 * len(pos)), nf)
        first = (np.cumsum(sizes) - sizes)[tpos][pos.reshape(-1)]
        return pos, verts, vstart, owner, np.concatenate(tf)[runs(first, nf)]

    def _hubs_farther(self, tids, m, pairs, gap: float, chunk: int = 2048) -> np.ndarray:
        """Which hub pairs (P, 2 rows) have meshes, as placed (not rounded), more than ``gap``
        apart: every two faces whose boxes come within ``gap`` (``grid_pairs``, the pairs moved
        apart as in ``_hubs_meet``) are more than ``gap`` apart along one of the axes that
        separate two triangles (``_triangles_within``)."""
        out = np.zeros(len(pairs), bool)
        for lo in range(0, len(pairs), chunk):
            pos, verts, vstart, owner, local = self._pair_faces(tids, m, pairs[lo:lo + chunk])
            tri = verts[vstart[pos.reshape(-1)][owner][:, None] + local]
            box_lo = np.minimum.reduceat(verts, vstart)
            span = float((np.maximum.reduceat(verts, vstart) - box_lo).max()) * 2 + 4 * gap
            tri[:, :, 0] += (owner // 2 * span)[:, None]  # each pair far from the others
            first = owner % 2 == 0
            a, b = np.flatnonzero(first), np.flatnonzero(~first)
            order = np.concatenate([a, b])
            t = tri[order]
            near = np.zeros(len(pos), bool)  # pairs with two faces that may be within gap
            for i, j in grid_pairs(t.min(axis=1), t.max(axis=1), gap, split=len(a)):
                close = _triangles_within(t[i], t[j], gap)
                near[owner[order[i[close]]] // 2] = True
            out[lo:lo + len(pos)] = ~near
        return out

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
        if self.excluded_beams is not None:  # rings a local union closes: neither cap nor strip
            for s, (p, sign) in enumerate(self.slots[n]):
                src = idx if sign > 0 else nb[:, s]
                inside[:, s] |= self.beam_excluded(src, p)
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
        new: dict = {}  # hub shapes not seen yet: key -> (node, own radius, neighbourhood)
        where: dict = {}  # key -> the node index (i, j, k, n) of its first hub (to name it in errors)
        per_node = []
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
            q = quantized(local, self.scale[n])
            own = np.full(len(reps), lat.template_radii[n])
            if lat.radius_field is not None:  # the hub's own graded radius, in its frame
                own = lat.node_balls(idx[reps])[1] / lat.group_factors(idx[reps, 0], idx[reps, 1], idx[reps, 2])
            own_q = np.round(own / self.scale[n]).astype(np.int64)
            keys = [(n, q[u].tobytes(), int(own_q[u])) for u in range(len(reps))]
            for u, key in enumerate(keys):
                if key not in self.templates and key not in new:
                    new[key] = (n, own[u], local[u])
                    where[key] = tuple(int(x) for x in idx[reps[u]])
            per_node.append((sel, inv.reshape(-1), keys))
        self._build_templates(new, where)
        for sel, inv, keys in per_node:
            tids[sel] = np.array([self.templates[key][0] for key in keys], np.int64)[inv]
        return tids, m, minv, info

    def _build_templates(self, new: dict, where: dict | None = None) -> None:
        """Templates of the hub shapes ``new`` (key -> (template node, own radius, neighbourhood
        (S, 4) with NaN rows for missing beams)), ids in the order of ``new``. Hubs with the same
        beam slots are built together (``hub_templates``: batches of one CHoCC topology),
        whatever their template node — the one-group form of group-mapped lattices
        (``Lattice.explicit``) has one template node per hub."""
        lat = self.lat
        by_beams: dict = {}
        for key, (n, own, local) in new.items():
            have = ~np.isnan(local[:, 3])
            by_beams.setdefault(have.tobytes(), []).append((key, n, own, local[have]))
        # tasks of at most TEMPLATE_CHUNK hubs, each from the hint its beam set had before this call:
        # the same tasks and results whatever the number of processes computing them
        tasks, args = [], []
        for hint_key, hubs in by_beams.items():  # the last hub with these beams: likely the same hull
            for lo, hi in _task_bounds(len(hubs)):
                keys, nodes, own, local = zip(*hubs[lo:hi])
                local = np.array(local).reshape(len(keys), -1, 4)
                tasks.append((hint_key, keys))
                args.append((lat.template_centers[list(nodes)], np.array(own), local[..., :3], local[..., 3],
                             self.style, self.levels, self.segments, self.hints.get(hint_key), self.min_edge,
                             self.fillet, self.batched, self.reps.get(hint_key, ())))
        if self.pool is not None and len(args) > 1:  # the largest first: no process is left with one at the end
            order = sorted(range(len(args)), key=lambda i: -len(args[i][1]))
            futures = dict(zip(order, [self.pool.submit(_hub_templates_task, args[i]) for i in order]))
            results = [self._named(futures[i].result, tasks[i][1], new, where) for i in range(len(args))]
        else:
            results = [self._named(partial(_hub_templates_task, a), t[1], new, where) for a, t in zip(args, tasks)]
        built = {}
        for (hint_key, keys), (packed, hint, reps) in zip(tasks, results):
            built.update(zip(keys, self.table.unpack(packed)))
            self.hints[hint_key] = hint
            self.reps[hint_key] = reps  # the topologies the next round of these beams tries first
        for key, (_, _, local) in new.items():
            have = ~np.isnan(local[:, 3])
            self.templates[key] = (len(self.templates), built[key], np.where(have, np.cumsum(have) - 1, -1))
            self.tpl_list.append(self.templates[key][1:])
            self.template_nodes.append(key[0])
        self.table.add(built[key] for key in new)  # in template-id order

    def _named(self, result, keys, new: dict, where: dict | None):
        """``result()`` of a template task over the hub shapes ``keys``; a junction it cannot build
        (``achocc.JunctionError``) becomes a PleError naming the hub's node index (i, j, k, n), the
        beam-patterns concerned and the geometric reason."""
        try:
            return result()
        except JunctionError as e:
            if e.hub is None or e.hub >= len(keys):
                raise
            key = keys[e.hub]
            n, _, local = new[key]
            slots = np.flatnonzero(~np.isnan(local[:, 3]))  # the hub's beams: its existing slots
            at = f"hub (i, j, k, n) = {(where or {}).get(key, ('?', '?', '?', n))}"
            names = []
            for b in e.beams:
                p, sign = self.slots[n][int(slots[b])]
                bp = self.lat.beams[p]
                names.append(f"{p} ({self._node_name(bp.n1)} -> {self._node_name(bp.n2)} {bp.offset}"
                             f"{', incoming' if sign < 0 else ''})")
            beams = f" [beam-pattern{'s' if len(names) > 1 else ''} {' and '.join(names)}]" if names else ""
            raise PleError(f"cannot mesh {at}: {e.reason}{beams}") from None

    def _node_name(self, n: int) -> str:
        name = self.lat.nodes[n].name
        return repr(name) if name is not None else str(n)

    # ----- assembly ---------------------------------------------------------------------
    def build(self, box: Region) -> tuple[np.ndarray, np.ndarray]:
        """Vertices and faces of the hubs of ``box`` and of the beams from them (to balls in
        the region), with capped disks where a beam leaves the region."""
        return self.assemble(self.prepare(box))

    def prefetch(self, boxes: list) -> None:
        """Build the hub templates of the nodes of ``boxes`` (own and ghosts) at once (a round of the stream):
        a batch of one CHoCC topology then spans several boxes, so its representative, built
        per hub, and its fixed costs are paid once per round rather than once per box."""
        nodes = np.unique(np.concatenate([self._box_nodes(box)[0] for box in boxes]), axis=0)
        if len(nodes):  # with the ghosts: the next box's first hubs are not built alone, in its own round
            self.instances(nodes)

    def _own_nodes(self, box: Region) -> np.ndarray:
        """The nodes (N, 4) of ``box`` that are meshed: kept by the filters, not excluded."""
        own = box.node_index(len(self.lat.nodes))
        return own[self.lat.keeps(own) & ~self.is_excluded(own)]

    def prepare(self, box: Region):
        """The first half of ``build``: the box's nodes (its own and the ghosts at the far ends
        of its beams) and their hub templates (built here if new). Boxes must be prepared in
        order, one at a time: template ids (and so the output) then do not depend on how many
        boxes are assembled at once."""
        idx, n_own = self._box_nodes(box)
        return (idx, n_own) + self.instances(idx)

    def _box_nodes(self, box: Region) -> tuple[np.ndarray, int]:
        """The nodes (N, 4) a box's mesh places: its own meshed nodes, then the ghosts at the far
        ends of its beams (in the region, outside the box). Returns (nodes, number of own)."""
        lat = self.lat
        own = self._own_nodes(box)
        # ghosts: the far ends of beams leaving the box but not the region
        ghosts = []
        for b in lat.beams:
            src = own[own[:, 3] == b.n1]
            dst = np.concatenate([src[:, :3] + [b.di, b.dj, b.dk], np.full((len(src), 1), b.n2)], axis=1)
            ok = _in(dst, self.region) & ~_in(dst, box) & ~self.is_excluded(dst)
            ok[ok] = self.lat.keeps(dst[ok])
            ghosts.append(dst[ok])
        ghosts = np.unique(np.concatenate(ghosts), axis=0) if ghosts else np.zeros((0, 4), np.int64)
        return np.concatenate([own, ghosts]).astype(np.int64), len(own)

    def assemble(self, prepared, pool: ArrayPool | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The second half of ``build``: vertices and faces of a prepared box (``prepare``). Reads
        the template cache only (and fills the strip cache), so boxes may be assembled at once.
        ``pool``: where the two arrays' memory comes from (give them back once read).

        Vertices: each hub's template, placed by its similarity, hub after hub (``assembly.place``);
        faces: the own hubs' template faces, then the caps where a beam leaves the region, then the
        beams' strips (``assembly.fill``)."""
        idx, n_own, tids, m, minv, info = prepared
        table = self.table.snapshot()  # holds every template of a prepared box
        rows = table[2]
        starts = np.zeros(len(idx) + 1, np.int64)
        np.cumsum(rows[tids, 2], out=starts[1:])
        offsets = starts[:-1]
        verts = np.empty((int(starts[-1]), 3)) if pool is None else pool.take((int(starts[-1]), 3), float)
        index = np.int32 if len(verts) < 2**31 else np.int64  # half the memory traffic of the largest array
        place(table, tids, offsets, m, verts)
        pieces = Pieces()
        # caps where a beam leaves the region
        tpl_list = self.tpl_list
        for sel, nb, exists, inside in info.values():
            own_sel = sel < n_own
            for s in range(nb.shape[1]):
                cut = sel[own_sel & exists[:, s] & ~inside[:, s]]
                for t in np.unique(tids[cut]):
                    tpl, slot_of = tpl_list[t]
                    pieces.add(tpl.caps[slot_of[s]], offsets[cut[tids[cut] == t]])
        self._beams(idx, n_own, tids, m, minv, offsets, tpl_list, pieces)
        total = int(rows[tids[:n_own], 4].sum()) + pieces.count()
        faces = np.empty((total, 3), index) if pool is None else pool.take((total, 3), index)
        pos = hub_faces(faces, table, tids[:n_own], offsets[:n_own])
        local, sides, pf0, pfn, a, b, pa0, pan = pieces.packed()
        fill(faces, pos, local, None, sides, pf0, pfn, a, b, pa0, pan)
        return verts, faces

    def _beams(self, idx, n_own, tids, m, minv, offsets, tpl_list, pieces: Pieces) -> None:
        """Strips of the beams leaving the box's hubs, added to ``pieces``; one zipper per
        (pattern, hub templates, relative similarity of the two frames) — the latter depends on
        (i, j) only."""
        lat = self.lat
        nu, nv, nw = lat.counts
        nn = len(lat.nodes)
        lin = ((idx[:, 0] * nv + idx[:, 1]) * nw + idx[:, 2]) * nn + idx[:, 3]
        srt = np.argsort(lin)
        n_tpl = int(tids.max()) + 1 if len(tids) else 1
        for p, b in enumerate(lat.beams):
            src = np.flatnonzero(idx[:n_own, 3] == b.n1)
            dst_idx = np.concatenate([idx[src, :3] + [b.di, b.dj, b.dk], np.full((len(src), 1), b.n2)], axis=1)
            ok = _in(dst_idx, self.region) & ~self.is_excluded(dst_idx) & ~self.beam_excluded(idx[src], p)
            ok[ok] = self.lat.keeps(dst_idx[ok])
            src, dst_idx = src[ok], dst_idx[ok]
            if len(src) == 0:
                continue
            dl = ((dst_idx[:, 0] * nv + dst_idx[:, 1]) * nw + dst_idx[:, 2]) * nn + dst_idx[:, 3]
            dst = srt[np.searchsorted(lin[srt], dl)]
            slot_a, slot_b = (int(x) for x in self.beam_slots[p])
            col = idx[src, 0] * nv + idx[src, 1]
            gkey = (tids[src] * n_tpl + tids[dst]) * (nu * nv) + col
            _, first, inv = np.unique(gkey, return_index=True, return_inverse=True)
            inv = inv.reshape(-1)
            order = np.argsort(inv, kind="stable")
            bounds = np.searchsorted(inv[order], np.arange(len(first) + 1))
            a0s, b0s = src[first], dst[first]
            rel = np.einsum("uij,ujk->uik", minv[a0s], m[b0s])
            qrel = quantized(rel[:, :3], 1e-9)
            keys = [(p, int(tids[a0]), int(tids[b0]), qrel[u].tobytes()) for u, (a0, b0) in enumerate(zip(a0s, b0s))]
            rings = [(tpl_list[tids[a0]][0].rings[tpl_list[tids[a0]][1][slot_a]],
                      tpl_list[tids[b0]][0].rings[tpl_list[tids[b0]][1][slot_b]]) for a0, b0 in zip(a0s, b0s)]
            self._add_strips(keys, rings, a0s, b0s, tids, rel, tpl_list, b)
            a_off, b_off = offsets[src[order]], offsets[dst[order]]
            for u in range(len(first)):
                which, local = self.strips[keys[u]]
                pieces.add(local, a_off[bounds[u]:bounds[u + 1]], b_off[bounds[u]:bounds[u + 1]], which)

    def _add_strips(self, keys, rings, a0s, b0s, tids, rel, tpl_list, beam) -> None:
        """Cache the strips (ring 0|1 per corner, template vertex id) of the beams ``keys`` not
        seen yet: zipped together (``_strips``) per pair of ring sizes."""
        todo: dict = {}
        for u, key in enumerate(keys):
            if key not in self.strips and key not in todo:
                todo[key] = u
        by_size: dict = {}
        for u in todo.values():
            by_size.setdefault((len(rings[u][0]), len(rings[u][1])), []).append(u)
        ca, cb = self.lat.template_centers[beam.n1], self.lat.template_centers[beam.n2]
        for us in by_size.values():
            pa = np.stack([tpl_list[tids[a0s[u]]][0].vertices[rings[u][0]] for u in us])
            pb = np.stack([tpl_list[tids[b0s[u]]][0].vertices[rings[u][1]] for u in us])
            f = _strips(pa, pb, rel[us], ca, cb)
            which, li = f[..., 1], f[..., 0]
            ring_a, ring_b = np.stack([rings[u][0] for u in us]), np.stack([rings[u][1] for u in us])
            k = np.arange(len(us))[:, None, None]
            local = np.where(which == 0, ring_a[k, np.where(which == 0, li, 0)],
                             ring_b[k, np.where(which == 1, li, 0)]).astype(np.int32)  # template vertex ids
            sides = which.astype(np.uint8)  # 1: the corner is on hub B's ring
            for k, u in enumerate(us):
                self.strips[keys[u]] = (sides[k], local[k])


def _unwrap_ring(theta: np.ndarray) -> np.ndarray:
    """Angles of counter-clockwise rings (..., m) relative to their first vertex, non-decreasing
    (coincident vertices whose round-off steps slightly backwards count as zero steps)."""
    step = np.diff(theta, axis=-1) % (2 * np.pi)
    step[step > 2 * np.pi - 1e-9] = 0.0
    return np.concatenate([np.zeros(theta.shape[:-1] + (1,)), np.cumsum(step, axis=-1)], axis=-1)


def _strips(pa: np.ndarray, pb: np.ndarray, rel: np.ndarray, ca, cb) -> np.ndarray:
    """Beam strip faces (K, k, 3, 2) as (local ring index, ring 0|1) of K beams whose rings have
    the same sizes, computed in hub A's frame: ring vertices pa (K, ma, 3) of hub A, pb (K, mb, 3)
    of hub B in its own frame, rel (K, 4, 4) B's frame in A's; ca, cb the two ball centres."""
    pb = np.einsum("kij,kmj->kmi", rel[:, :3, :3], pb) + rel[:, None, :3, 3]
    d = unit_rows(np.einsum("kij,j->ki", rel[:, :3, :3], cb) + rel[:, :3, 3] - ca)
    e1, e2 = perpendicular_frames(d)

    def ang(p):
        q = p - ca
        return np.arctan2(np.einsum("kmi,ki->km", q, e2), np.einsum("kmi,ki->km", q, e1))

    a_ccw = np.arange(pa.shape[1])[::-1]  # hub rings run clockwise about their outward normal
    f = zippers(ang(pa[:, a_ccw]), ang(pb))
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
        raise PleError(f"--fillet: a fillet needs the refined style, not {echo(style)}")
    return float(fillet)


def resolve_style(style: str, levels: int | None, segments: int | None) -> tuple[int, int]:
    style_named(style)
    levels = DEFAULT_LEVELS if levels is None else int(levels)
    segments = DEFAULT_SEGMENTS if segments is None else int(segments)
    if not 0 <= levels <= MAX_LEVELS:
        raise PleError(f"levels {levels}: expected 0..{MAX_LEVELS}")
    if not 3 <= segments <= 1024:
        raise PleError(f"segments {segments}: expected 3..1024")
    return levels, segments


def tessellation_box(lat: Lattice, region, box, style: str = "refined", levels: int | None = None,
                     segments: int | None = None, grid: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3) of the hubs of one ``box`` of ``region`` (and of the
    beams from them, capped where a beam leaves the region): a part of a partitioned mesh. Boxes
    of one region close up exactly as the streamed tessellation's do (``iter_triangles``).
    ``grid``: the region's ``output_grid`` when the caller knows it (it streams the region's
    bounds otherwise: a whole-region pass per box)."""
    levels, segments = resolve_style(style, levels, segments)
    if style == "balls-beams":
        raise PleError("boxes of a mesh need a closed style (refined, cnt or chocc)")
    if clip_bodies(lat):
        raise PleError("a lattice filling a body by 'any' is cut at the body's surface in one piece: "
                       "mesh it without parts")
    r = lat.region(region)
    return Tessellator(lat, r, style, levels, segments, grid=grid).build(lat.region(box))


def tessellate(lat: Lattice, region=None, style: str = "refined", levels: int | None = None,
               segments: int | None = None, check_clean: bool = True, fillet: float | None = None,
               cut: bool = True, unclean=None, contain=None) -> trimesh.Trimesh:
    """The mesh of a region (default: the whole lattice) as one trimesh.

    ``levels``: refinement levels of ``refined`` (default 4); ``segments``: generators per full
    circle of ``chocc`` corridors (default 16). Watertight and consistently oriented for
    chocc, cnt and refined; ``balls-beams`` is a preview.

    Unclean hubs (``ple.meshing.unclean``) are found first (``check_clean``); if there are any, the
    clean rest is meshed on the fast path and united with their balls and beams by manifold3d;
    ``mesh.metadata["ple_unclean"]`` holds the report (None when not checked). A lattice filling a
    body by ``any`` is cut at the body's surface (``ple.meshing.skin.clip_to_bodies``) unless
    ``cut`` is False (for a skin, which cuts and unites in one run of Booleans); ``contain`` runs
    that cut's Booleans (``clip_to_bodies``: in a child process that a signal stops). ``unclean``: the
    region's report when the caller has it already (``checked_stream``), so the check runs once."""
    import trimesh
    levels, segments = resolve_style(style, levels, segments)
    bodies = clip_bodies(lat)
    lat, r = lat.per_hub(region)  # groups not similar (Möbius, TMI): every hub its own template
    if style == "balls-beams":

        ev = lat.evaluate(r)
        return balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes)
    tess = Tessellator(lat, r, style, levels, segments, check_fillet(fillet, style))
    report = None
    if unclean is not None and lat.group_map is None:  # rows of this region's evaluation
        report, ev = unclean, lat.evaluate(r)
    elif check_clean:
        report, ev = tess.find_unclean()
    if report is not None and report.element_pairs is not None and len(report.nodes):
        verts, faces = build_with_unions(tess, ev, report)
    else:
        verts, faces = tess.build(r)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    mesh.remove_unreferenced_vertices()
    mesh.metadata["ple_unclean"] = report
    return clip_to_bodies(mesh, bodies if cut else [], contain)  # a lattice filling a body by `any` ends at its surface


def leave_to_unions(tess: Tessellator, ev, report) -> list:
    """Tell the fast path which hubs and beams the local unions of ``report`` mesh
    (``ple.meshing.unions``); returns the clusters."""
    cl = clusters(report, ev.beam_nodes, ev.center, ev.radius, ball_segments(tess.segments))
    idx = np.asarray(ev.node_index, np.int64)
    hubs = np.concatenate([c.hubs for c in cl]) if cl else np.zeros(0, np.int64)
    beams = np.concatenate([c.beams for c in cl]) if cl else np.zeros(0, np.int64)
    bn = np.asarray(ev.beam_nodes, np.int64).reshape(-1, 2)
    pattern = np.asarray(ev.beam_index, np.int64)[:, 3]
    tess.exclude(idx[hubs], np.concatenate([idx[bn[beams, 0], :3], pattern[beams, None]], axis=1))
    report.clusters = len(cl)
    estimate_unions(report, cl, ev)
    return cl


FORESIGHT_PAIRS = 20_000_000  # candidate ball pairs up to which ``foreseen_union`` looks (more: the check decides)


@dataclass
class ForeseenUnion:
    """The largest local union ``foreseen_union`` finds from the balls alone."""

    hubs: int
    beams: int
    ball_pairs: int  # overlapping balls in the whole region
    slabs: int
    bytes: int


def foreseen_union(lat: Lattice, region=None, segments: int | None = None) -> ForeseenUnion | None:
    """The largest local union foreseen before the unclean check, cheaply, from the balls alone:
    two balls that overlap (centres nearer than their radii's sum) are unclean hubs of one local
    union (their meshes would meet, and no free beam joins them), so the connected groups of the
    overlap graph, with the beams at their hubs, are within the check's clusters. Their largest
    one's estimate (``unions.piece_estimate``, or its largest slab's) is a lower bound of what the
    check will find. None when no ball overlaps another, or when more than ``FORESIGHT_PAIRS``
    candidate pairs would have to be looked at (the check then decides). A region of more than
    ``SAMPLED_GROUPS`` groups is looked at whole only where its corners or middle overlap.
    ``segments``: the mesh's (its unions' balls: ``unclean.ball_segments``)."""
    lat, r = lat.per_hub(region)
    if r.groups > SAMPLED_GROUPS and not any(len(_overlapping_balls(lat.evaluate(b))) for b in _sample_blocks(r)):
        return None
    ev = lat.evaluate(r)
    pairs = _overlapping_balls(ev, FORESIGHT_PAIRS)
    if pairs is None or not len(pairs):
        return None
    label = component_labels(len(ev.center), pairs)
    sizes = np.bincount(label[np.unique(pairs)], minlength=int(label.max()) + 1)
    hubs = np.flatnonzero(label == int(np.argmax(sizes)))
    bn = np.asarray(ev.beam_nodes, np.int64).reshape(-1, 2)
    beams = np.flatnonzero(np.isin(bn, hubs).any(axis=1))
    peak, count = slabs.union_peak(Cluster(hubs, beams, segments=ball_segments(segments)), ev.center, ev.radius, bn)
    return ForeseenUnion(len(hubs), len(beams), len(pairs), count, int(peak))


def _overlapping_balls(ev, limit: int | None = None) -> np.ndarray | None:
    """(P, 2) the pairs of an evaluation's balls that overlap (their boxes' pairs from
    ``queries.overlaps.grid_pairs``, then the centres' distance); None past ``limit`` candidates."""
    c, rad = np.asarray(ev.center, float), np.asarray(ev.radius, float)
    out, seen = [], 0
    for i, j in grid_pairs(c - rad[:, None], c + rad[:, None], 0.0):
        block = np.stack([np.asarray(i, np.int64), np.asarray(j, np.int64)], axis=1)
        seen += len(block)
        if limit is not None and seen > limit:
            return None
        d = np.linalg.norm(c[block[:, 0]] - c[block[:, 1]], axis=1)
        out.append(block[d < rad[block[:, 0]] + rad[block[:, 1]]])
    return np.concatenate(out) if out else np.zeros((0, 2), np.int64)


SAMPLED_GROUPS = 4096  # regions beyond this many groups are looked at in ``_sample_blocks`` first


def _sample_blocks(r: Region) -> list:
    """Blocks of up to 4 groups a side at the region's eight corners and its middle."""
    out = []
    for corner in itertools.product((0, 1, 2), repeat=3):
        if 1 in corner and corner != (1, 1, 1):
            continue
        lo = []
        for (a, b), k in zip(((r.i0, r.i1), (r.j0, r.j1), (r.k0, r.k1)), corner):
            n = min(4, b - a)
            lo.append((a, a + n) if k == 0 else (b - n, b) if k == 2 else ((a + b - n) // 2, (a + b - n) // 2 + n))
        out.append(Region(lo[0][0], lo[0][1], lo[1][0], lo[1][1], lo[2][0], lo[2][1]))
    return out


def estimate_unions(report, cl: list, ev) -> None:
    """The largest local union's peak bytes (``slabs.union_peak``: one union's, or its largest
    slab's), counted from the hub neighbourhoods before any union runs, with its hubs, beams,
    overlapping pairs and slabs."""
    report.union_bytes = 0
    n = len(ev.center)
    for c in cl:
        peak, count = slabs.union_peak(c, ev.center, ev.radius, ev.beam_nodes)
        if peak > report.union_bytes:
            ids = np.concatenate([np.asarray(c.hubs, np.int64), n + np.asarray(c.beams, np.int64)])
            report.union_bytes, report.union_hubs, report.union_beams = peak, len(c.hubs), len(c.beams)
            report.union_pairs, report.union_slabs = len(report.pairs_within(np.sort(ids))), count


def build_with_unions(tess: Tessellator, ev, report) -> tuple[np.ndarray, np.ndarray]:
    """The region's mesh in memory: the fast path without the clusters of ``report``, and their
    local unions, welded where they share their rings' vertices, put on the output grid (the
    mesh every float32 file of it holds)."""
    cl = leave_to_unions(tess, ev, report)
    pieces = list(union_pieces(tess, ev, cl, report))  # first: a cluster may grow into the fast path's hubs
    v, f = weld_chunks([tess.build(tess.region), *pieces])
    v, f, _ = weld(v, f, tess.grid)  # on the float32 grid, as every file holds it
    return v, f


MAX_CLUSTER_GROWTH = 16  # times a cluster takes in the clean junctions whose rings its union touched


def union_pieces(tess: Tessellator, ev, cl: list, report=None, chunk: int = 512):
    """The meshes (vertices, faces) of the clusters ``cl`` (``leave_to_unions``), one by one: each
    open along the contact rings it shares with the fast path, whose vertices it takes from the
    hub templates placed as the boxes place them (``assembly.place``), ``chunk`` clusters' rings
    at a time. A union that touches one of its rings (something of the cluster reaches that
    clean junction) takes the junction's hub in as a ball, with its beams (merging any cluster
    that holds one), and the fast path leaves them out too: so the pieces are held until every
    cluster is settled, and drawn before the boxes are built. With ``report`` (``leave_to_unions``'),
    a cluster is first cut across its free beams into smaller unions (``unions.split``). Small
    clusters are united in batches (``unions.unite_batch``), copies of a shape from its piece
    (``unions.ShapeCache``)."""
    yield from _UnionQueue(tess, ev, cl, report, chunk).run()


def _triangles_within(t1: np.ndarray, t2: np.ndarray, gap: float) -> np.ndarray:
    """(K,) bool: triangle pairs (K, 3, 3) each not proven more than ``gap`` apart by their
    projections on 14 axes (x, y, z, both normals, the nine cross products of their edges: the
    separating axes of two triangles): the gap of the projections on a unit axis is at most their
    distance."""
    e1, e2 = t1[:, [1, 2, 0]] - t1, t2[:, [1, 2, 0]] - t2
    axes = np.concatenate([np.broadcast_to(np.eye(3), (len(t1), 3, 3)),
                           np.cross(e1[:, 0], e1[:, 1])[:, None], np.cross(e2[:, 0], e2[:, 1])[:, None],
                           np.cross(e1[:, :, None], e2[:, None, :]).reshape(-1, 9, 3)], axis=1)  # (K, 14, 3)
    norm = np.linalg.norm(axes, axis=2)
    p1, p2 = np.einsum("kai,kvi->kav", axes, t1), np.einsum("kai,kvi->kav", axes, t2)
    gaps = np.maximum(p2.min(axis=2) - p1.max(axis=2), p1.min(axis=2) - p2.max(axis=2))
    gaps = np.where(norm > 0, gaps / np.where(norm > 0, norm, 1.0), -np.inf)
    return gaps.max(axis=1) <= gap


def merged(pieces, triangles: int = 1 << 16):
    """Pieces (vertices, faces) joined into chunks of at least ``triangles`` faces (the last
    fewer): one encoding per chunk instead of one per piece (copies of a small cluster are many)."""
    vs, fs, at, n = [], [], 0, 0
    for v, f in pieces:
        vs.append(v)
        fs.append(np.asarray(f) + at)
        at += len(v)
        n += len(f)
        if n >= triangles:
            yield np.concatenate(vs), np.concatenate(fs)
            vs, fs, at, n = [], [], 0, 0
    if fs:
        yield np.concatenate(vs), np.concatenate(fs)


MAX_BATCHED = BATCH_TRIANGLES // 8  # clusters up to this estimate (input triangles) are united in batches
MAX_WAITING = 64  # copies of batched shapes held before the batch is united (their rings are held too)


class _UnionQueue:
    """The clusters of ``union_pieces`` on their way to pieces: pending, batched, settled."""

    def __init__(self, tess: Tessellator, ev, cl: list, report, chunk: int):
        self.tess, self.ev, self.report, self.chunk = tess, ev, report, chunk
        self.idx = np.asarray(ev.node_index, np.int64)
        self.bn = np.asarray(ev.beam_nodes, np.int64).reshape(-1, 2)
        self.pattern = np.asarray(ev.beam_index, np.int64)[:, 3]
        self.pending = deque(cl)
        self.done: dict = {}  # id -> (cluster, pieces), held until all are settled (a later one may grow into it)
        self.rings_of: dict = {}
        self.cache = ShapeCache(tess.grid)  # copies of a cluster's shape take its piece, moved (steady lattices)
        self.batch: list = []  # (cluster, rings, key, anchor, ring keys) to unite at once
        self.waiting: list = []  # (cluster, rings, shape): copies of a batched shape, settled after the batch
        self.batched: set = set()  # the keys and ``like`` keys of the batch's shapes
        self.unsettled: list = []  # clusters of a flushed batch not settled yet
        self.gone: set = set()  # ids of clusters merged into a grown one
        self.united = 0  # unions made (the other pieces are copies)
        self.slab_copies = 0  # slabs copied from a period's (``slabs._Period``)

    def run(self):
        while self.pending:
            c = self.pending.popleft()
            rg = self._rings(c)
            if self.report is not None and len(c.hubs) > 1:
                self._flush()
                self._settle(c, rg, cut=True)
                continue
            shape = self.cache.shape(c, self.ev.center, self.ev.radius, self.bn, rg)
            if shape.key is not None and shape.key in self.batched:  # a moved copy of a batched shape
                self._wait(c, rg, shape)
                continue
            piece = self.cache.get(shape, rg)
            if piece is not None:
                self.done[id(c)] = (c, [piece])
            elif rg and piece_estimate(c)[0] <= MAX_BATCHED:
                like = self.cache.like(shape)
                if like is not None and like in self.batched:  # a turned copy of a batched shape
                    self._wait(c, rg, shape)
                    continue
                self.batch.append((c, rg, shape))
                self.batched |= {like, shape.key}  # its turned copies and its moved ones wait
                if sum(piece_estimate(b[0])[0] for b in self.batch) >= BATCH_TRIANGLES:
                    self._flush()
            else:
                self._flush()
                self._settle(c, rg)
        self._flush()
        if self.report is not None:
            self.report.united = self.united
            self.report.slab_copies = self.slab_copies
        for _, pieces in self.done.values():
            yield from pieces

    def _wait(self, c, rg, shape) -> None:
        """Hold a copy of a batched shape until the batch is united (at most MAX_WAITING are held)."""
        self.waiting.append((c, rg, shape))
        if len(self.waiting) >= MAX_WAITING:
            self._flush()

    def _rings(self, c) -> dict:
        if id(c) not in self.rings_of:  # this cluster and the next ones' rings, placed at once
            part = [c, *itertools.islice(self.pending, self.chunk - 1)]
            self.rings_of.update(zip(map(id, part), _cluster_rings(self.tess, self.idx, self.bn, self.pattern, part)))
        return self.rings_of.pop(id(c))

    def _flush(self) -> None:
        """Unite the batch; its failures and the copies waiting for it are settled one by one."""
        if not self.batch:
            return
        batch, self.batch = self.batch, []
        self.batched = set()
        ev = self.ev
        pieces = [None] if len(batch) == 1 else unite_batch([b[0] for b in batch], ev.center, ev.radius, self.bn,
                                                            [b[1] for b in batch], self.tess.grid)
        for (c, rg, shape), piece in zip(batch, pieces):
            if piece is not None:
                self.united += 1
                self.cache.put(shape, rg, piece)
                self.done[id(c)] = (c, [piece])
            else:
                self.unsettled.append((c, rg))
        for c, rg, shape in self.waiting:
            piece = self.cache.get(shape, rg)
            if piece is not None:
                self.done[id(c)] = (c, [piece])
            else:
                self.unsettled.append((c, rg))
        self.waiting = []
        while self.unsettled:
            c, rg = self.unsettled.pop(0)
            if id(c) not in self.gone:
                self._settle(c, rg)

    def _settle(self, c, rg, cut: bool = False) -> None:
        """One cluster's pieces, each a copy or its union; with ``cut``, the cluster cut across its
        free beams (``unions.split``) first. The cluster grows (and is cut anew) while pieces touch
        clean junctions; it is united whole when it is not cut, or when a piece touches a cut ring."""
        bn = self.bn
        for _ in range(MAX_CLUSTER_GROWTH):
            parts, cut_rings = [c], {}
            if cut:
                got = split(c, self.report, self.ev.center, self.ev.radius, bn, SEPARATION_GRIDS * self.tess.grid,
                            self._linear if self.tess.lat.group_map is None else None)
                if got is None:
                    self._settle(c, rg)
                    return
                parts, cut_rings = got
            pieces, touched = [], []
            of_beam: dict = {}  # the cluster's ring keys by beam row, looked up per part
            for k in rg:
                of_beam.setdefault(k[0], []).append(k)
            for part in parts:
                prg = rg
                if part is not c:
                    own = set(part.hubs.tolist())
                    prg = {k: rg[k] for j in part.beams.tolist() for k in of_beam.get(j, ()) if int(bn[k]) not in own}
                    prg.update({(j, CUT): cut_rings[(j, CUT)] for j, _ in part.halves.tolist()})
                got = self._pieces(part, prg)
                if isinstance(got, RingTouchedError):
                    if any(e == CUT for _, e in got.ring):
                        self._settle(c, rg)
                        return
                    touched += got.ring
                else:
                    pieces += got
            if not touched:
                self.done[id(c)] = (c, pieces)
                return
            c, rg = self._grow(c, touched)
        raise PleError(f"an unclean cluster of {len(c.hubs):,} hubs and {len(c.beams):,} beams keeps "
                       "touching the clean junctions around it")

    def _linear(self, rows) -> np.ndarray:
        """The linear parts (K, 3, 3) of the similarities that place the groups of beams ``rows``
        (their first ends'): the frames of their cut rings (``unions.split``)."""
        g = self.idx[self.bn[np.asarray(rows, np.int64), 0], :3]
        return self.tess.lat.group_matrices(g[:, 0], g[:, 1], g[:, 2])[:, :3, :3]

    def _shifts(self) -> np.ndarray:
        """The translations among the similarities that step the lattice's groups, in world axes
        (``G U G⁻¹``, ``G V G⁻¹``, ``G W G⁻¹`` where those are translations): where the lattice
        repeats, its slabs are copies (``slabs._Period``, which checks each copy element by
        element). None for a group map (Möbius, warps)."""
        lat = self.tess.lat
        if lat.group_map is not None:
            return np.zeros((0, 3))
        m = lat.group_matrices([0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1])
        step = m[1:] @ np.linalg.inv(m[0])[None]
        linear = np.abs(step[:, :3, :3] - np.eye(3)).max(axis=(1, 2)) <= 1e-12
        return step[linear, :3, 3]

    def _pieces(self, c, rg):
        """A cluster's pieces: from the cache, or its union (put in the cache), or, when its union
        is planned in slabs (``slabs.union_peak``), its slabs' (``slabs.unite_in_slabs``); the
        RingTouchedError when a union touches one of its rings."""
        if slabs.union_peak(c, self.ev.center, self.ev.radius, self.bn)[1] > 1:  # as it was estimated
            try:
                got, copies = unite_in_slabs_stoppable(c, self.ev.center, self.ev.radius, self.bn, rg,
                                                       self.tess.grid, self._shifts())
            except RingTouchedError as exc:
                return exc
            self.united += len(got) - copies
            self.slab_copies += copies
            return got
        piece = self._piece(c, rg)
        return piece if isinstance(piece, RingTouchedError) else [piece]

    def _piece(self, c, rg):
        """A cluster's piece from the cache, or its union (put in the cache); the RingTouchedError
        when the union touches one of its rings."""
        shape = self.cache.shape(c, self.ev.center, self.ev.radius, self.bn, rg)
        piece = self.cache.get(shape, rg)
        if piece is None:
            try:
                piece = unite_stoppable(c, self.ev.center, self.ev.radius, self.bn, rg, self.tess.grid)
            except RingTouchedError as exc:
                return exc
            self.united += 1
            self.cache.put(shape, rg, piece)
        return piece

    def _grow(self, c, ring_keys: list):
        """Cluster c with the clean junctions at ``ring_keys`` taken in (``_grown``), the
        clusters holding them merged; the fast path leaves them out. Returns (cluster, rings)."""
        bn, idx, pattern = self.bn, self.idx, self.pattern
        others = (list(self.pending) + [d for d, _ in self.unsettled if id(d) not in self.gone]
                  + [d for d, _ in self.done.values()])
        c, merged = _grown(c, sorted({int(bn[j, e]) for j, e in ring_keys}), bn, others)
        gone = {id(p) for p in merged}
        self.gone |= gone
        self.pending = deque(q for q in self.pending if id(q) not in gone)
        for g in gone:
            self.rings_of.pop(g, None)
            self.done.pop(g, None)
        self.tess.exclude_more(idx[c.hubs], np.concatenate([idx[bn[c.beams, 0], :3], pattern[c.beams, None]], axis=1))
        return c, _cluster_rings(self.tess, idx, bn, pattern, [c])[0]


def _cluster_rings(tess: Tessellator, idx, bn, pattern, part: list) -> list:
    """Per cluster of ``part``, its rings (beam row, end) -> vertices (k, 3) placed as the boxes
    place them: the contact rings of the clean junctions at the ends of its beams."""
    ends = []
    for k, c in enumerate(part):
        own = set(c.hubs.tolist())
        ends += [(k, int(j), e) for j in c.beams.tolist() for e in (0, 1) if int(bn[j, e]) not in own]
    rings: list = [{} for _ in part]
    if not ends:
        return rings
    at = np.array(ends, np.int64).reshape(-1, 3)
    rows = bn[at[:, 1], at[:, 2]]
    tids, m, _, _ = tess.instances(idx[rows])
    verts, offsets = tess._placed_hubs(tids, m, np.arange(len(rows)))
    first, size = tess._vertex_lists(tids, tess.beam_slots[pattern[at[:, 1]], at[:, 2]])
    placed = verts[np.repeat(offsets, size) + tess.id_lists[runs(first, size)]]
    for (k, j, e), ring in zip(ends, np.split(placed, np.cumsum(size)[:-1])):
        rings[k][(j, e)] = ring
    return rings


def _grown(c, hubs_in: list, bn, others: list):
    """Cluster ``c`` with the hubs ``hubs_in`` taken in (balls) with every beam at them, and with
    the other clusters that share one of those hubs or beams merged in. Returns (cluster, the
    merged clusters)."""
    beams = np.flatnonzero(np.isin(bn, hubs_in).any(axis=1))
    merged = [p for p in others if np.isin(p.beams, beams).any() or np.isin(p.hubs, hubs_in).any()]
    hubs = np.unique(np.concatenate([c.hubs, hubs_in, *[p.hubs for p in merged]])).astype(np.int64)
    allb = np.unique(np.concatenate([c.beams, beams, *[p.beams for p in merged]])).astype(np.int64)
    return Cluster(hubs, allb, segments=c.segments), merged


def iter_triangles(lat: Lattice, region=None, style: str = "refined", levels: int | None = None,
                   segments: int | None = None, max_groups: int = 1 << 14, fillet: float | None = None, _tess=None,
                   workers: int = 1, encode=None):
    """Stream the region's mesh box by box (bounded memory) as pairs (vertices (V, 3), faces
    (k, 3)); hubs next to a box boundary are repeated in both boxes (their vertices, not faces).
    ``workers`` threads assemble boxes at once; the stream is the same for any number. With
    ``encode``, each box is yielded as ``encode((vertices, faces))``, computed by the same thread
    right after the box (e.g. a file's records: the box's arrays are freed at once, and at most
    workers + 1 boxes are alive)."""
    levels, segments = resolve_style(style, levels, segments)
    r = lat.region(region)
    if style == "balls-beams" or clip_bodies(lat):  # a preview; or one mesh cut at a body's surface
        mesh = tessellate(lat, r, style, levels, segments, fillet=fillet)
        chunk = np.asarray(mesh.vertices), np.asarray(mesh.faces)
        yield chunk if encode is None else encode(chunk)
        return
    lat, r = lat.per_hub(r)  # groups not similar (Möbius, TMI): every hub its own template
    workers = max(1, int(workers))
    tess = _tess if _tess is not None else Tessellator(lat, r, style, levels, segments, check_fillet(fillet, style),
                                                        workers=workers)
    # a box of at most about BOX_TRIANGLES triangles (estimated from above): workers + 1 of them are alive
    per_group = len(lat.nodes) * hub_triangles(mean_degree(lat), style, levels, segments)
    max_groups = int(max(1, min(max_groups, BOX_TRIANGLES // max(per_group, 1))))
    try:
        yield from _stream_boxes(tess, list(lat.iter_slabs(max_groups=max_groups, region=r)), workers, encode)
    finally:
        tess.close_pool()


def _stream_boxes(tess: Tessellator, boxes: list, workers: int, encode=None):
    """``iter_triangles``' boxes: prepared in order by one thread, assembled (and encoded) by ``workers``."""

    arrays = ArrayPool()

    def build(ready):
        if encode is None:  # the caller keeps the arrays
            return tess.assemble(ready.result())
        chunk = tess.assemble(ready.result(), arrays)
        out = encode(chunk)
        arrays.give(*chunk)  # read by now: the next box reuses their memory
        return out

    def prepare(b):
        if len(boxes) > 1 and b % TEMPLATE_ROUND == 0:  # rounds fixed by the box list: the same for any workers
            tess.prefetch(boxes[b:b + TEMPLATE_ROUND])
        return tess.prepare(boxes[b])

    # boxes are prepared (hub templates) in order by one thread and assembled by ``workers``
    # threads (numpy releases the GIL in its large array operations), the next ones while the
    # caller writes this one: at most workers + 1 boxes are held at a time, and the output does
    # not depend on the number of workers. Preparation runs a round ahead of assembly (prepared
    # boxes are small), so the next round's templates are built while this round is assembled
    with ThreadPoolExecutor(max_workers=1) as prep:
        yield from ordered_map(build, _ahead(prep, prepare, len(boxes), workers + 1 + TEMPLATE_ROUND), workers,
                               threads=True)


def _ahead(pool, fn, n: int, lookahead: int):
    """Futures of fn(0), …, fn(n - 1) on ``pool``, each submitted ``lookahead`` items before it is
    yielded (the executor runs them in order when it has one thread)."""
    pending: deque = deque()
    try:
        for b in range(n):
            pending.append(pool.submit(fn, b))
            if len(pending) > lookahead:
                yield pending.popleft()
        while pending:
            yield pending.popleft()
    finally:
        for f in pending:  # the consumer stopped early: nothing more is prepared
            f.cancel()


def ordered_map(fn, items, workers: int = 1, threads: bool = False):
    """``map(fn, items)`` computed by ``workers`` threads, in order, with at most workers + 1 results
    pending (bounded memory whatever the number of items). One worker computes in the caller's
    thread unless ``threads`` (then the next result is computed while the caller uses this one)."""
    workers = max(1, int(workers))
    if workers == 1 and not threads:
        yield from map(fn, items)
        return
    with ThreadPoolExecutor(max_workers=workers) as pool:
        pending: deque = deque()
        for item in items:
            pending.append(pool.submit(fn, item))
            if len(pending) > workers:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


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


def quantized(x: np.ndarray, quantum: float) -> np.ndarray:
    """Integer keys (..., 2) of values x (NaN: a key of its own): whole multiples of
    ``quantum`` while they fit in 2⁵⁰, beyond that the exponent and the leading 40 bits of the
    mantissa (a relative quantum), so huge coordinates (a similarity scaled by 1e10) never
    overflow into one shared key."""
    x = np.asarray(x, float)
    nan = np.isnan(x)
    x = np.where(nan, 0.0, x)
    small = np.abs(x) < quantum * 2.0**50
    mant, ex = np.frexp(np.where(small, 0.0, x))
    a = np.where(small, np.round(np.where(small, x, 0.0) / quantum), np.round(mant * 2.0**40)).astype(np.int64)
    b = np.where(small, 0, ex.astype(np.int64) + 4096)
    b = np.where(nan, -1, b)
    return np.stack([a, b], axis=-1)


def output_grid(lat: Lattice, region=None) -> float:
    """The float32 snap grid of a region's output (``ple.meshing.weld.grid_spacing`` of its
    bounds): one grid for every streamed box and every job part of the region, so they close up."""
    return grid_spacing(*lat.bounds(lat.region(region)))


def smallest_radius(lat: Lattice, region=None) -> float:
    """The smallest ball radius of a region (world units): the smallest template radius times
    the smallest group scale factor, found at the region's corner groups (powers of
    similarities scale monotonically along each axis). Lattices placed by other maps, or with
    graded radii (no lower bound known): inf."""
    if lat.group_map is not None or lat.radius_field is not None or not len(lat.nodes):
        return float("inf")
    r = lat.region(region)
    corners = np.array([[i, j, k] for i in (r.i0, max(r.i1 - 1, r.i0)) for j in (r.j0, max(r.j1 - 1, r.j0))
                        for k in (r.k0, max(r.k1 - 1, r.k0))])
    f = lat.group_factors(corners[:, 0], corners[:, 1], corners[:, 2])
    return float(np.min(lat.template_radii) * np.min(f))


def check_bytes(lat: Lattice, region=None) -> float:
    """Peak bytes of ``checked_stream``'s cleanliness check of a region (0 beyond
    MAX_CHECK_GROUPS groups: not checked), estimated before it runs."""
    r = lat.region(region)
    if r.groups > MAX_CHECK_GROUPS:
        return 0.0
    return CHECK_ELEMENT_BYTES * (region_nodes(lat, r) + region_beams(lat, r))


def checked_stream(lat: Lattice, region=None, style: str = "refined", levels: int | None = None,
                   segments: int | None = None, max_groups: int = 1 << 14, fillet: float | None = None,
                   workers: int = 1, encode=None, grid: float | None = None):
    """The streamed mesh of a region: (report, chunks). Regions up to MAX_CHECK_GROUPS groups are
    checked first (``ple.meshing.unclean``; the check's hub templates are reused by the stream);
    report is None for larger regions (not checked). A region with unclean hubs streams each
    cluster's local union (``ple.meshing.unions``), then its boxes without the clusters, which
    meet the unions exactly along contact rings: memory is bounded by a box and a cluster."""
    levels, segments = resolve_style(style, levels, segments)
    if style == "balls-beams":
        raise PleError("a checked stream needs a closed style (refined, cnt or chocc)")
    if clip_bodies(lat):  # cut at a body's surface: one Boolean of the whole mesh, in memory
        return None, None
    lat, r = lat.per_hub(region)  # groups not similar (Möbius, TMI): every hub its own template
    tess = Tessellator(lat, r, style, levels, segments, check_fillet(fillet, style), grid=grid,
                        workers=max(1, int(workers)))  # grid: the region's output_grid when the caller has it
    report, ev = tess.find_unclean() if r.groups <= MAX_CHECK_GROUPS else (None, None)
    boxes = iter_triangles(lat, r, style, levels, segments, max_groups, _tess=tess, workers=workers, encode=encode)
    if report is None or not len(report.nodes):
        return report, boxes
    cl = leave_to_unions(tess, ev, report)  # before the first box: the boxes leave the clusters' rings open
    pieces = union_pieces(tess, ev, cl, report)
    # the pieces first: a cluster that grows takes hubs from the boxes, which are built after it
    return report, itertools.chain(pieces if encode is None else map(encode, merged(pieces)), boxes)
