"""A cluster too large for one union, cut into slabs: memory bounded by the slab, not the cluster.

A cluster with no free beam (``unions.split`` finds none: thick octets, all-shrunk junctions)
can hold most of a lattice. It is cut by planes normal to its longest axis into slabs of at most
``SLAB_TRIANGLES`` input triangles, and each slab is one manifold3d union. The estimate checked
before anything is made counts every element whole in each slab it reaches (``plan_slabs``); the
slabs are planned as they are made, from their elements as clipped (``_SlabContext.next_plane``):

1. Each ball and beam is a convex solid (``unions.Elements``, made when a slab needs it). One
   that crosses a cut plane is clipped there *before* the union: its cap on the plane is the
   polygon of its own edges cut by the plane, from its one hull, without crossings on the chord
   of their neighbours (``_strict_hull``): the same floats on both sides.
2. The slab's clipped elements are united. Its cap on each cut plane is the union of those
   polygons (what meets on the plane is what crosses it: the same elements on both sides), and
   it is triangulated anew from its boundary alone (``_recapped``). Its corners are the shared
   floats; its edges' crossings are computed by each Boolean from different faces.
3. The slab goes on the output grid with its seams pinned (``unclean.on_grid``), its caps are
   removed, and its low seam is walked loop by loop onto the last slab's high seam
   (``_matched``: every vertex within ``LOOSE`` tolerances of its partner, the faces near a moved
   one checked exactly): the slabs meet on identical vertices, as the pieces of ``unions`` meet
   the fast path along its rings.

A seam that does not match moves its plane and makes the last slab again (up to 2
``SEAM_TRIES`` times); a slab the grid folds inside is made once more, then the balls are turned
(as ``unions.unite_cluster`` does).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PleError
from .selfcheck import self_intersections
from .unclean import TURN_TRIES, match_rows, on_grid
from .unions import (
    UNION_TRIANGLE_BYTES,
    Elements,
    ball_triangles,
    cut_bound,
    manifold3d_module,
    open_rings,
    piece_estimate,
    stoppable,
)
from .weld import sorted_edges

SLAB_TRIANGLES = 1_500_000  # estimated input triangles of one slab's union (about 0.9 GB at UNION_TRIANGLE_BYTES)
SLAB_INPUT = 300_000  # input triangles of one slab's union as made (manifold3d's batch union grows faster
# than its input: one slab of 1.5e6 ran for minutes past 3 GB, where 2.3e5 took 8 s and 0.25 GB)
SEAM_TOLERANCE = 2.0**-32  # of the cluster's size: a vertex this near a plane is on it; a seam's sure vertex
LOOSE = 2.0**14  # tolerances (2^-18 of the size): how far apart two sides put a crossing of nearly tangent edges
SEAM_TRIES = 4  # plane positions tried before a cluster is refused
CLEARANCE = 2.0**-20  # of the cluster's size: how far a cut plane stays from every element's vertex
BALL_SHIFT = 0.25  # of a slab: how far a plane moves to keep off the balls (``_SlabContext.plane``)
SLAB_GAIN = 0.5  # the largest slab's share of the whole cluster's input, at most, for a cut to pay
PLANE_STEPS = 4096  # positions along the cluster, besides its elements' low ends, where a slab may end


def element_triangles(cluster) -> np.ndarray:
    """Input triangles of each element of a cluster, in ``element_hulls``' order, from above
    (as ``unions.piece_estimate``): a polygonal ball per hub, two balls' worth per beam or half."""
    ball = ball_triangles(cluster.segments)
    n = len(cluster.hubs), len(cluster.beams), len(cluster.halves)
    return np.concatenate([np.full(n[0], ball), np.full(n[1] + n[2], 2 * ball)]).astype(np.int64)


def element_extents(cluster, center, radius, beam_nodes) -> np.ndarray:
    """(E, 2, 3): each element's box (low, high corner), from its balls' bounding spheres."""
    c, r = np.asarray(center, float), np.asarray(radius, float) * cut_bound(cluster.segments)
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    ends = np.concatenate([np.stack([cluster.hubs, cluster.hubs], 1), bn[cluster.beams],
                           bn[cluster.halves[:, 0]] if len(cluster.halves) else np.zeros((0, 2), np.int64)])
    lo = np.minimum(c[ends[:, 0]] - r[ends[:, 0], None], c[ends[:, 1]] - r[ends[:, 1], None])
    hi = np.maximum(c[ends[:, 0]] + r[ends[:, 0], None], c[ends[:, 1]] + r[ends[:, 1], None])
    return np.stack([lo, hi], axis=1)


def plan_slabs(weights: np.ndarray, extents: np.ndarray, limit: int = SLAB_TRIANGLES):
    """(axis, cuts) for elements of ``weights`` (input triangles) and ``extents`` (E, 2, 3): the
    cluster's longest axis, and planes along it at which no slab holds more than ``limit``
    triangles where that can be had (a slab holds every element that reaches into it); cuts is
    empty when the whole fits. Greedy: each slab grows element by element (in order of their low
    ends) until the next would pass the limit."""
    size = extents[:, 1].max(axis=0) - extents[:, 0].min(axis=0)
    axis = int(np.argmax(size))
    if weights.sum() <= limit:
        return axis, np.zeros(0)
    lo, hi = extents[:, 0, axis], extents[:, 1, axis]
    order = np.argsort(lo, kind="stable")
    cuts, load, first = [], 0, None  # first: the low end of the slab's first element
    for i in order:
        if load + weights[i] > limit and first is not None and lo[i] > first:
            cut = float(lo[i])  # the plane at this element's low end: it and those after go to the next slab
            cuts.append(cut)
            first = cut
            load = int(weights[(hi > cut) & (lo < cut)].sum())  # elements crossing the plane are in both
        if first is None:
            first = float(lo[i])
        load += int(weights[i])
    return axis, np.asarray(cuts, float)


def slab_plan_bytes(cluster, center, radius, beam_nodes, limit: int | None = None) -> tuple[int, int]:
    """(peak bytes of a cluster's largest slab union, number of cut planes): the whole
    cluster's, and 0, when it fits one union."""
    w = element_triangles(cluster)
    ext = element_extents(cluster, center, radius, beam_nodes)
    axis, cuts = plan_slabs(w, ext, SLAB_TRIANGLES if limit is None else limit)
    return int(max(slab_loads(w, ext[:, 0, axis], ext[:, 1, axis], cuts))) * UNION_TRIANGLE_BYTES, len(cuts)


def union_peak(cluster, center, radius, beam_nodes) -> tuple[int, int]:
    """(peak bytes, slabs) of a cluster's union as ``tessellate`` runs it: one union
    (``unions.piece_estimate``), or, past ``SLAB_TRIANGLES`` input triangles and where the plan
    cuts it, its slabs (the largest one's bytes). A plan whose largest slab holds more than
    ``SLAB_GAIN`` of the whole (elements that each reach across most of the cluster: balls far
    larger than the cell) is not cut: every slab would be nearly the whole union again."""
    tris, peak = piece_estimate(cluster)
    if tris <= SLAB_TRIANGLES:
        return peak, 1
    slab_peak, cuts = slab_plan_bytes(cluster, center, radius, beam_nodes)
    gain = slab_peak <= SLAB_GAIN * tris * UNION_TRIANGLE_BYTES
    return (slab_peak, cuts + 1) if cuts and gain else (peak, 1)


def slab_loads(weights, lo, hi, cuts) -> list:
    """Input triangles of each slab between ``cuts`` (every element reaching into it)."""
    edges = [-math.inf, *cuts.tolist(), math.inf]
    return [int(weights[(hi > a) & (lo < b)].sum()) for a, b in zip(edges[:-1], edges[1:])]


def unite_in_slabs(cluster, center, radius, beam_nodes, rings: dict, grid: float, limit: int = SLAB_TRIANGLES,
                   made: int = SLAB_INPUT, shifts=()):
    """(the pieces (vertices, faces), how many of them are copies) of a cluster cut into slabs
    (module docstring), each open along
    its seams and along the rings it shares with clean junctions (``unions.unite_cluster``'s
    ``rings``). Tries the balls all turned one way, then each its own (``TURN_TRIES`` after the
    first: a cluster this large is a thick lattice, whose symmetric beams meet tangentially on
    balls as they are, and a failed try costs a slab), each at up to ``SEAM_TRIES`` positions of
    each plane. Only the elements of one slab are held at a time. ``limit``: the estimate's slab
    (``plan_slabs``: whether the cluster is cut at all); ``made``: each slab's input triangles as
    its elements are made and clipped (``_SlabContext.next_plane``). ``shifts``: translations (K, 3)
    that may map the lattice onto itself (``_Period``): along the best of them the slabs of one
    period are united once and the periods after it that are its translates are copies."""
    manifold3d = manifold3d_module()
    weights = element_triangles(cluster)
    ext = element_extents(cluster, center, radius, beam_nodes)
    axis, cuts = plan_slabs(weights, ext, limit)
    if not len(cuts):
        raise PleError("a cluster that fits one union is not cut into slabs")
    last = None
    for turns in TURN_TRIES[1:]:
        make = Elements(manifold3d, cluster, center, radius, beam_nodes, rings, turns)
        period = _Period.best(make, ext, shifts, grid) if turns != "each" else None  # each its own: no translates
        for per in ((period, None) if period is not None else (None,)):
            try:
                return _slabs(make, weights, ext, axis if per is None else per.axis, grid, made, per)
            except PleError as exc:  # a plane that no try could place: the balls turned, as unite_cluster does
                last = exc
    raise PleError(f"an unclean cluster of {len(cluster.hubs):,} hubs and {len(cluster.beams):,} beams cut "
                   f"into {len(cuts) + 1} slabs does not join ({last})")


def unite_in_slabs_stoppable(cluster, center, radius, beam_nodes, rings: dict, grid: float, shifts=()) -> tuple:
    """``unite_in_slabs`` in a child process that a signal stops (``unions.stoppable``)."""
    return stoppable(unite_in_slabs, cluster, center, radius, beam_nodes, rings, grid, SLAB_TRIANGLES, SLAB_INPUT,
                     shifts)


def _made(make, i: int, axis: int):
    """Element i as (its hull's vertices, faces, its low and high end along ``axis``, its
    vertices' and its edges' low and high ends along it, each sorted). The hull itself is not
    kept (manifold3d's structure is about 10 times the arrays, and a slab plan makes thousands
    ahead): a slab makes it again from its vertices."""
    m = make.hull(i).to_mesh64()
    v, f = np.asarray(m.vert_properties[:, :3], float), np.asarray(m.tri_verts, np.int64)
    x = v[:, axis]
    e = x[sorted_edges(f, len(v))]
    return v, f, float(x.min()), float(x.max()), np.sort(x), np.sort(e.min(axis=1)), np.sort(e.max(axis=1))


class SeamMismatchError(PleError):
    """The two sides of a seam do not match: the plane between them is moved."""


def _slabs(make, weights, ext, axis, grid, limit, period=None):
    """Every slab's piece (module docstring). Each plane is the farthest from the last one at
    which the slab between them holds at most ``limit`` input triangles, counted from its
    elements as clipped (``_SlabContext.next_plane``), placed off the balls and rings where it
    can be, and off the vertices of the elements that reach it; the elements reaching past it
    are kept for the next slab, the others let go. A seam that does not match moves its plane
    and makes the last slab again (up to 2 ``SEAM_TRIES`` times); a slab the grid folds is made
    once more with its high plane moved, then given up (the caller turns the balls: a fold inside
    a slab is a symmetric lattice's, which no plane moves). With a ``period`` (``_Period``), the
    slabs of one period are made and the periods after it that are its translates are copied."""
    lo, hi = ext[:, 0, axis], ext[:, 1, axis]
    size = float((ext[:, 1].max(axis=0) - ext[:, 0].min(axis=0)).max()) or 1.0
    ctx = _SlabContext(make, weights, lo, hi, axis, grid, size)
    if period is not None:
        period.start(lo, hi, ctx.clear)
    pieces: list = []
    copies = 0
    last = None  # the last slab: (its low plane, the seam it took, its high plane)
    a, prev, tries, beyond = -math.inf, None, 0, -math.inf
    while True:
        if period is not None and period.ready(a):  # the template period is made: its translates are copied
            n = len(pieces)
            a, prev, copied = period.copies(ctx, a, prev, pieces)
            copies += len(pieces) - n
            if copied:
                last, tries, beyond = copied, 0, a
                ctx.let_go(a)
            period.idle(a)
        b = math.inf
        cut = ctx.next_plane(a, limit, beyond)
        if math.isfinite(cut):
            gap = cut - (a if math.isfinite(a) else ctx.span[0])
            b = ctx.plane(cut + _nudge(tries) * gap, a)
            if b is None and (period is None or not period.recording):  # no place near it: the slab reaches to
                beyond = cut  # the next element's end
                continue
        if period is not None and period.recording:  # the template's last slab ends on the period's plane
            close = period.closing
            if b is None or b > close - CLOSE_SLACK * (close - a):
                b = close
        elif period is not None and period.window and a < period.window[0] and b > period.window[1]:  # the plane that
            b = ctx.plane(period.window[1], a)  # starts a template: in its window, off the balls where it can be
            if b is None or not period.window[0] <= b <= period.window[1]:
                b = period.window[1]
        try:
            piece, seam, b, info = ctx.slab(a, b, prev)
        except SeamMismatchError:
            period = None
            if last is None or tries >= 2 * SEAM_TRIES:
                raise
            tries += 1  # the low plane moves: the last slab is made again up to it
            a0, prev0, _ = last
            moved = ctx.plane(a + _nudge(tries) * (a - a0 if math.isfinite(a0) else a - ctx.span[0]), a0)
            if moved is None:
                raise
            pieces[-1], prev, a = *ctx.slab(a0, moved, prev0)[:2], moved
            last = (a0, prev0, a)
            continue
        except PleError:  # a fold on the grid inside the slab: once more with the high plane moved,
            period = None
            if not math.isfinite(b) or tries:  # then the balls are turned (the caller)
                raise
            tries += 1
            continue
        if piece is not None:
            pieces.append(piece)
            last = (a, prev, b)
        if period is not None and not period.made(b, piece, info):
            period = None
        if not math.isfinite(b):
            return pieces, copies
        prev, a, tries, beyond = seam, b, 0, b
        ctx.let_go(b)


CLOSE_SLACK = 0.2  # of a slab: a template slab planned to end this near the period's plane ends on it


class _Period:
    """A translation ``t`` that maps the cluster onto itself where it can (``sigma``: element i to
    the element that is its translate, -1 where there is none), and the slabs along ``axis``
    (t's largest component, ``s`` > 0) that it maps to slabs (planes ``s`` apart). A period
    [q, q + s] whose elements all have translates, and whose translate holds only translates
    (``window``: where q may be), is made slab by slab (the template); then each slab of each
    later period is the template's slab moved by p t, for as long as the elements reaching it are
    exactly the p-th images of the template slab's (``copies``); then the next window is sought.
    A copy is moved onto the grid by a multiple of four grid steps (so its rounding to the grid,
    and to twice the grid, is the template's, which ``on_grid`` checked), its seams by p t
    exactly; its low seam is walked onto the last slab's (``_matched``), and the faces near either
    seam are checked exactly (``_check_moved``). A copy that fails ends the copies: the slabs
    after it are made."""

    def __init__(self, axis: int, t: np.ndarray, sigma: np.ndarray, grid: float, tol: float):
        self.axis, self.t, self.sigma, self.grid, self.tol = axis, t, sigma, grid, tol
        self.s = float(t[axis])
        self.template: list = []
        self.recording, self.closing, self.window = False, math.inf, None

    @staticmethod
    def best(make, ext, shifts, grid: float) -> _Period | None:
        """The shift whose copies would cover the most of the cluster, or None when none would
        cover any."""
        shifts = np.asarray(shifts, float).reshape(-1, 3)
        size = float((ext[:, 1].max(axis=0) - ext[:, 0].min(axis=0)).max()) or 1.0
        best, most = None, 0
        for t in shifts:
            axis = int(np.argmax(np.abs(t)))
            if abs(t[axis]) <= CLEARANCE * size:
                continue
            t = t if t[axis] > 0 else -t
            sigma = shift_map(make, t, SEAM_TOLERANCE * size)
            # the share of elements with a translate, less the periods a run of copies leaves made
            # at its ends (the first, the template, the last, and a half for the planes)
            n = float((sigma >= 0).mean()) - 3.5 * t[axis] / float(np.ptp(ext[:, :, axis]))
            if n > most:
                best, most = _Period(axis, t, sigma, grid, SEAM_TOLERANCE * size), n
        return best

    def start(self, lo, hi, clear) -> None:
        has_pre = np.zeros(len(self.sigma), bool)
        has_pre[self.sigma[self.sigma >= 0]] = True
        s, none = self.s, self.sigma < 0
        # a template at q needs every element reaching [q, q + s] to have an image, and every one
        # reaching [q + s, q + 2s] a preimage: the positions each element rules out
        self.blocked = sorted(zip(np.concatenate([lo[none] - s, lo[~has_pre] - 2 * s]).tolist(),
                                  np.concatenate([hi[none], hi[~has_pre] - s]).tolist()))
        self.clear, self.begin, self.end = clear, float(lo.min()), float(hi.max())
        self.idle(-math.inf)

    def idle(self, a: float) -> None:
        """No template: the next window past the plane ``a`` (None when there is none)."""
        self.template, self.recording, self.window = [], False, None
        x = max(a, self.begin) + self.clear
        for u, w in self.blocked:  # sorted by their starts: the first gap past x
            if w + self.clear <= x:
                continue
            if u - self.clear > x:
                break
            x = w + self.clear
        else:
            return
        if x < self.end:
            nxt = min((u for u, _ in self.blocked if u - self.clear > x), default=math.inf)
            self.window = (x, nxt - self.clear)

    def ready(self, a: float) -> bool:
        return bool(self.template) and not self.recording and a == self.closing

    def made(self, b, piece, info) -> bool:
        """Take a slab just made, ending at the plane ``b``; False when the template broke."""
        if self.recording:
            if piece is None:
                return False
            self.template.append((b, piece, info))
            if b == self.closing:
                self.recording = False
            return b <= self.closing
        if self.window is None or not math.isfinite(b):
            return True
        if b > self.window[1]:
            self.idle(b)
        elif b >= self.window[0]:  # the period from b is the template
            self.recording, self.closing, self.q0 = True, b + self.s, b
        return True

    def copies(self, ctx, a, prev, pieces):
        """The template's translates, appended to ``pieces`` while they hold; (the plane where
        they end, its seam, the last slab's (low plane, seam it took, high plane) or None)."""
        q = [self.q0] + [t[0] for t in self.template[:-1]]  # each template slab's low plane
        cur = [info[0] for *_, info in self.template]
        last, p = None, 1
        while True:
            for i, (_, piece, info) in enumerate(self.template):
                img = self.sigma[cur[i]] if len(cur[i]) else cur[i]
                if (img < 0).any():
                    return a, prev, last
                cur[i] = img
                b = q[i + 1] + p * self.s if i + 1 < len(q) else q[0] + (p + 1) * self.s
                want = ctx.reach(a, b)
                if len(want) != len(img) or not np.array_equal(want, np.sort(img)):
                    return a, prev, last
                try:
                    got, seam = _copied(piece, info, p * self.t, self.grid, prev, self.tol, self.axis, b)
                except SeamMismatchError:
                    return a, prev, last
                pieces.append(got)
                last, a, prev = (a, prev, b), b, seam
                ctx.let_go(a)
            p += 1


def shift_map(make, t, tol: float) -> np.ndarray:
    """(E,) each element of a cluster (``Elements``' order) to the one that is its translate by
    ``t`` (balls of the same radius whose centres are t apart within ``tol``; beams between
    translated balls), -1 where there is none and for elements with a ring (the fast path's
    floats, which a translate does not carry)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    hubs = np.asarray(make.cluster.hubs, np.int64)
    sigma = np.full(make.count, -1, np.int64)
    if not len(hubs):
        return sigma
    c, rad = make.c[hubs], make.rad[hubs]
    d, j = cKDTree(c).query(c + t, distance_upper_bound=tol)
    ok = np.isfinite(d)
    ok[ok] = np.abs(rad[j[ok]] - rad[ok]) <= tol
    sigma[:len(hubs)][ok] = j[ok]
    image = np.full(int(max(hubs.max(), make.bn.max(initial=0))) + 1, -1, np.int64)
    image[hubs[ok]] = hubs[j[ok]]
    beams = np.asarray(make.cluster.beams, np.int64)
    if len(beams):
        ends = make.bn[beams]
        inside = np.isin(ends, hubs).all(axis=1)
        where = {(int(x), int(y)): k for k, (x, y) in enumerate(ends.tolist())}
        to = image[ends]
        for k in np.flatnonzero(inside & (to >= 0).all(axis=1)).tolist():
            m = where.get((int(to[k, 0]), int(to[k, 1])), -1)
            if m >= 0 and inside[m]:
                sigma[len(hubs) + k] = len(hubs) + m
    return sigma


def _copied(piece, info, t, grid, prev, tol, axis, b):
    """The template slab's ``piece`` moved by ``t`` (``_Period``): (piece, its high seam)."""
    v, f = piece
    _, low_edges, high_ids, at = info
    out = v + np.round(t / (4 * grid)) * (4 * grid)
    seam_ids = np.unique(np.concatenate([low_edges.reshape(-1), high_ids]))
    out[seam_ids] = v[seam_ids] + t
    out[high_ids, axis] = b
    if (prev is None) != (not len(low_edges)):
        raise SeamMismatchError("a copied slab has a seam where the last slab had none, or none where it had one")
    if len(low_edges):  # its low seam onto the last slab's floats (the faces near them checked there)
        out = _matched(out, f, low_edges[:, ::-1], prev, tol)
    if len(high_ids):
        _check_moved(out, f, high_ids)
    return (out, f), (out[high_ids], at)


def _nudge(t: int) -> float:
    """The fraction of a slab by which try t moves a plane: 0, then ±0.06, ±0.12, …"""
    return 0.0 if t == 0 else (0.06 * ((t + 1) // 2)) * (1 if t % 2 else -1)


class _SlabContext:
    """What the slabs of one cluster share: its elements (made when a slab needs them, let go when
    no later slab does), the balls and rings a plane keeps off, the tolerances."""

    def __init__(self, make, weights, lo, hi, axis, grid, size):
        self.make, self.weights, self.lo, self.hi, self.axis, self.grid = make, weights, lo, hi, axis, grid
        # where a slab may end: every element's low end, and a fine grid between (a row of a lattice
        # starts at one end, and a slab to the next row's may hold far more than the limit)
        self.ends = np.unique(np.concatenate([lo, np.linspace(lo.min(), hi.max(), PLANE_STEPS)]))
        self.tol, self.clear = SEAM_TOLERANCE * size, CLEARANCE * size
        self.ring_pts = {k: np.asarray(make.rings[k], float) for k in make.keys}
        self.rings_at = [(float(r[:, axis].min()), float(r[:, axis].max())) for r in self.ring_pts.values()]
        self.balls_at = list(zip(lo[:make.hubs].tolist(), hi[:make.hubs].tolist()))
        self.span = (float(lo.min()), float(hi.max()))
        self.built: dict = {}  # element -> _made's

    def plane(self, c: float, a: float) -> float | None:
        """A plane near ``c`` above ``a``, off the balls and rings where it can be (None: none).
        Off the balls only within ``BALL_SHIFT`` of the slab from ``a`` to ``c``: on curved rows
        the balls' spans along the axis cover it end to end, and the nearest place off them
        would make one slab of most of the cluster."""
        within = (max(a, self.span[0]) + self.clear, self.span[1] - self.clear)
        shift = BALL_SHIFT * (c - max(a, self.span[0]))
        b = _nearest_free(c, self.rings_at + self.balls_at, self.clear, *within)
        if b is None or abs(b - c) > shift:
            b = _nearest_free(c, self.rings_at, self.clear, *within)
        return None if b is None or b <= a else b

    def next_plane(self, a: float, limit: int, beyond: float) -> float:
        """The position past ``beyond`` (``ends``) farthest from the plane ``a`` at which the slab
        from ``a`` holds at most ``limit`` input triangles (``load``), or inf when all the rest
        does; the first position past ``beyond`` when even that slab holds more. Doubling steps
        over the positions, then halving: the load only grows with the slab."""
        ends = self.ends[np.searchsorted(self.ends, max(a, beyond) + self.clear, "right"):]
        if not len(ends) or self.load(a, math.inf, limit) <= limit:
            return math.inf
        good, step = -1, 1  # ends[good] fits (-1: none tried)
        while good + step < len(ends) and self.load(a, float(ends[good + step]), limit) <= limit:
            good += step
            step *= 2
        bad = min(good + step, len(ends))  # ends[bad] does not fit (or is past the last)
        while bad - good > 1:
            mid = (good + bad) // 2
            good, bad = (mid, bad) if self.load(a, float(ends[mid]), limit) <= limit else (good, mid)
        return float(ends[max(good, 0)])

    def load(self, a: float, b: float, limit: int) -> int:
        """Input triangles of the slab between a and b, from above: an element inside it has its
        own; a clipped one at most 2P - 4, P its vertices between the planes and its edges
        crossing them (the points of its hull, ``_clip``), and never more than its own. Counted
        from the elements' unclipped estimates first (``element_triangles``): only when those
        pass ``limit`` are the elements made and counted, nearest ``a`` first, until the count
        passes ``limit`` (then it is returned as it stands: only ``<= limit`` is asked)."""
        reach = np.flatnonzero((self.hi > a) & (self.lo < b))
        if int(self.weights[reach].sum()) <= limit:
            return int(self.weights[reach].sum())
        total = 0
        for i in reach[np.argsort(self.lo[reach], kind="stable")].tolist():
            if total > limit:
                break
            total += self.clipped(i, a, b)
        return total

    def clipped(self, i: int, a: float, b: float) -> int:
        """Triangles of element i between the planes a and b, from above (``load``)."""
        if i not in self.built:
            self.built[i] = _made(self.make, i, self.axis)
        _, f, elo, ehi, xs, emin, emax = self.built[i]
        if elo >= a and ehi <= b:
            return len(f)
        p = int(np.searchsorted(xs, b) - np.searchsorted(xs, a, "right"))
        for c in (a, b):
            if math.isfinite(c):
                p += int(np.searchsorted(emin, c) - np.searchsorted(emax, c))
        return min(len(f), max(2 * p - 4, 0))

    def reach(self, a: float, b: float) -> np.ndarray:
        """The elements reaching into the slab between a and b (sorted)."""
        return np.flatnonzero((self.hi > a) & (self.lo < b))

    def slab(self, a: float, b: float, prev):
        """(piece, high seam, the high plane as placed, (the elements reaching in, and the
        piece's low seam edges, high seam vertices and edges: ``_slab_piece``)) of the slab
        between a and b."""
        axis, clear = self.axis, self.clear
        for _ in range(64):  # the elements reaching in; the plane stepped past their vertices
            want = self.reach(a, b)
            for i in want.tolist():
                if i not in self.built:
                    self.built[i] = _made(self.make, i, axis)
            near = [e[4] for i, e in self.built.items() if e[2] - clear <= b <= e[3] + clear]
            if not near or np.abs(np.concatenate(near) - b).min() > clear:
                break
            b += clear
        solids = []
        clip = self.make.manifold3d.Manifold.hull_points
        for i in want.tolist():
            v, f, elo, ehi = self.built[i][:4]
            if ehi > a and elo < b:
                solids.append(clip(v) if elo >= a and ehi <= b else clip(_clip(v, f, a, b, axis)))
        if not solids:  # a gap between elements (nothing crosses its planes): no piece
            if prev is not None and len(prev[0]):
                raise SeamMismatchError("a slab of an unclean cluster holds nothing past a seam")
            return None, None, b, None
        piece, seam, ends = _slab_piece(self.make.manifold3d, solids, a, b, axis, prev, self.ring_pts, self.grid,
                                        self.tol)
        return piece, seam, b, (want, *ends)

    def let_go(self, a: float) -> None:
        """Forget the elements that end below the plane ``a`` (no later slab reaches them)."""
        self.built = {i: e for i, e in self.built.items() if e[3] > a}


def _slab_piece(manifold3d, solids, a, b, axis, prev, ring_pts, grid, tol):
    """One slab's union, on the grid with its seams pinned, opened along them (its low seam given
    the last slab's floats, ``_matched``) and along its rings; returns (piece, its high seam for
    the next slab: (points, directed edges into them), (its low seam's directed edges, its high
    seam's vertices and the edges into them, in the piece's vertices))."""
    out = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add).to_mesh64()
    v, f = np.array(out.vert_properties[:, :3], float), np.asarray(out.tri_verts, np.int64)
    low, high = _on_plane(v, a, axis, tol), _on_plane(v, b, axis, tol)
    if (prev is None) != (not low.any()):
        raise SeamMismatchError("a slab of an unclean cluster has a seam where the last slab had none, or none where "
                                "it had one")
    for on, c in ((low, a), (high, b)):  # each cap made of its boundary alone: its inner vertices go
        if on.any():
            f = _recapped(manifold3d, v, f, on, c, axis)
    used = np.zeros(len(v), bool)
    used[f.reshape(-1)] = True
    low, high = low & used, high & used
    seams = [v[low], v[high]]
    own_keys = [k for k, r in ring_pts.items() if a < r[0, axis] < b]
    pinned = [ring_pts[k] for k in own_keys]
    centre = v.mean(axis=0)
    reach = float(np.linalg.norm(v - centre, axis=1).max())
    v, f = on_grid(v, f, grid, centre[None], reach, rings=pinned + [s for s in seams if len(s)])
    low, high = _rows(v, seams[0]), _rows(v, seams[1])
    caps = (low[f].all(axis=1) & _flat(v, f, a, axis)) | (high[f].all(axis=1) & _flat(v, f, b, axis))
    f = f[~caps]
    open_edges = _open(f, len(v))
    on_low, on_high = low[open_edges].all(axis=1), high[open_edges].all(axis=1)
    if prev is not None:  # this side runs its seam the other way round
        v = _matched(v, f, open_edges[on_low][:, ::-1], prev, tol)
    if pinned:
        v, f = open_rings(v, f, pinned, own_keys, seams=open_edges[on_low | on_high])
    elif not (on_low | on_high).all():
        raise PleError("a slab of an unclean cluster is open off its seams")
    used = np.unique(f)  # the caps' inner vertices go
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    seam = open_edges[on_high]  # directed as this slab's faces leave them
    ids, at = np.unique(seam, return_inverse=True)
    at = at.reshape(-1, 2)
    return (v[used], remap[f]), (v[ids], at), (remap[open_edges[on_low]], remap[ids], at)


def _recapped(manifold3d, v, f, on, c, axis) -> np.ndarray:
    """``f`` with its cap on the plane at ``c`` (faces with every corner on it) triangulated anew
    from the cap's boundary loops alone (``manifold3d.triangulate``, which keeps their edges):
    a Boolean leaves inner vertices in a cap (corners of one element's polygon inside another's),
    which the grid could tie to the seam."""
    cap = on[f].all(axis=1) & _flat(v, f, c, axis)
    if not cap.any():
        return f
    cf = f[cap]
    nxt = _successors(_open(cf, len(v)))
    if nxt is None:
        raise SeamMismatchError("a seam of a slab is pinched (a vertex on two of its loops)")
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, x = [], start
        while x not in seen:
            seen.add(x)
            loop.append(x)
            x = nxt[x]
        loops.append(np.asarray(loop, np.int64))
    t = v[cf]
    up = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])[:, axis].sum() > 0  # the cap faces +axis
    other = [(axis + 1) % 3, (axis + 2) % 3]
    if not up:
        loops = [lp[::-1] for lp in loops]
    tri = np.asarray(manifold3d.triangulate([v[lp][:, other] for lp in loops]), np.int64)
    new = np.concatenate(loops)[tri.reshape(-1)].reshape(-1, 3)
    return np.concatenate([f[~cap], new if up else new[:, ::-1]])


def _nearest_free(c: float, blocked: list, clear: float, lo: float, hi: float) -> float | None:
    """The position nearest ``c`` within (lo, hi) outside every interval of ``blocked`` (each
    widened by ``clear``), or None when they cover all of it."""
    iv = sorted((a - clear, b + clear) for a, b in blocked)
    merged: list = []
    for a, b in iv:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    for a, b in merged:
        if a < c < b:
            options = [x for x in (a - clear, b + clear) if lo < x < hi]
            return min(options, key=lambda x: abs(x - c)) if options else None
    return c


def _clip(v: np.ndarray, f: np.ndarray, a: float, b: float, axis: int) -> np.ndarray:
    """The points whose hull is the convex solid (v, f) between the planes ``a`` and ``b`` along
    ``axis``: its vertices between them and its edges' crossings of each plane, each crossing
    computed from the edge's lower-numbered end (so both slabs of a plane get the same floats)."""
    x = v[:, axis]
    keep = v[(x >= a) & (x <= b)]
    e = sorted_edges(f, len(v))
    out = [keep]
    for c in (a, b):
        if not math.isfinite(c):
            continue
        p, q = v[e[:, 0]], v[e[:, 1]]
        cross = (p[:, axis] - c) * (q[:, axis] - c) < 0
        p, q = p[cross], q[cross]
        t = (c - p[:, axis]) / (q[:, axis] - p[:, axis])
        hit = p + t[:, None] * (q - p)
        hit[:, axis] = c
        out.append(hit[_strict_hull(np.delete(hit, axis, axis=1))])
    return np.concatenate(out)


COLLINEAR = 2.0**-34  # of a cap's size: a crossing this close to the chord of its neighbours is no corner


def _strict_hull(p: np.ndarray) -> np.ndarray:
    """Indices of the corners of the convex hull of 2-D points ``p``, without points on (or within
    ``COLLINEAR`` of) the chord of their neighbours: a beam's planar side quad, cut, gives its
    diagonal's crossing on the line of the other two, which a 3-D hull keeps or drops depending
    on the rest of the solid; so a cap polygon is the same on both sides of its plane."""
    if len(p) < 3:
        return np.arange(len(p))
    order = np.lexsort((p[:, 1], p[:, 0]))
    size = float(np.ptp(p, axis=0).max()) or 1.0
    tol = COLLINEAR * size

    def chain(idx):
        out: list = []
        for i in idx:
            while len(out) >= 2:
                a, b = p[out[-2]], p[out[-1]]
                cross = (b[0] - a[0]) * (p[i][1] - a[1]) - (b[1] - a[1]) * (p[i][0] - a[0])
                if cross > tol * np.hypot(p[i][0] - a[0], p[i][1] - a[1]):
                    break
                out.pop()
            out.append(int(i))
        return out

    lower, upper = chain(order), chain(order[::-1])
    return np.asarray(lower[:-1] + upper[:-1], np.int64)


def _on_plane(v, c, axis, tol) -> np.ndarray:
    """Vertices on the plane at ``c`` (within ``tol``), put exactly on it."""
    if not math.isfinite(c):
        return np.zeros(len(v), bool)
    on = np.abs(v[:, axis] - c) <= tol
    v[on, axis] = c
    return on


def _flat(v, f, c, axis) -> np.ndarray:
    """Faces lying on the plane at ``c``."""
    return (v[f][:, :, axis] == c).all(axis=1) if math.isfinite(c) else np.zeros(len(f), bool)


def _rows(v, points) -> np.ndarray:
    return match_rows(v, points) >= 0 if len(points) else np.zeros(len(v), bool)


def _open(f, n) -> np.ndarray:
    """Directed edges (E, 2) of ``f`` without their reverse: where the mesh is open."""
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    m = max(n, 1)
    return d[~np.isin(d[:, 0] * m + d[:, 1], d[:, 1] * m + d[:, 0])]


def _matched(v, f, edges, ref, tol) -> np.ndarray:
    """``v`` with the vertices of this slab's low seam (``edges``: (E, 2), directed as the last
    slab's run) at the last slab's seam points (``ref``: (points (S, 3), directed edges (S, 2)
    into them)). The two are walked loop by loop from a vertex within ``tol`` of exactly one
    reference point; each vertex on the way must lie within ``LOOSE`` tolerances of its partner
    (a crossing of two nearly tangent cap edges, which the two Booleans place apart), and the
    faces near a vertex that moved must not meet after the move (exact). Else SeamMismatchError."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    points, ref_edges = ref
    mine = np.unique(edges)
    if len(mine) != len(points) or len(edges) != len(ref_edges):
        raise SeamMismatchError(f"a seam between two slabs has {len(points)} vertices on one side and {len(mine)} "
                                "on the other")
    nxt_mine, nxt_ref = _successors(edges), _successors(ref_edges)
    if nxt_mine is None or nxt_ref is None:
        raise SeamMismatchError("a seam between two slabs is pinched (a vertex on two of its loops)")
    loose = LOOSE * tol
    d, j = cKDTree(points).query(v[mine], k=min(2, len(points)))
    d, j = d.reshape(len(mine), -1), j.reshape(len(mine), -1)
    sure = (d[:, 0] <= tol) & ((d[:, 1] > loose) if d.shape[1] > 1 else True)
    partner = dict(zip(mine.tolist(), j[:, 0].tolist()))
    out = v.copy()
    done: set = set()
    for x0 in mine[sure].tolist():
        if x0 in done:
            continue
        x, a = x0, partner[x0]
        while True:
            if x in done or np.linalg.norm(v[x] - points[a]) > loose:
                raise SeamMismatchError("a seam between two slabs does not match (its loops run apart)")
            out[x] = points[a]
            done.add(x)
            x, a = nxt_mine[x], nxt_ref[a]
            if x == x0:
                if a != partner[x0]:
                    raise SeamMismatchError("a seam between two slabs does not match (its loops differ)")
                break
    if len(done) != len(mine):
        raise SeamMismatchError("a seam between two slabs does not match (a loop without a sure vertex)")
    moved = np.flatnonzero((out != v).any(axis=1))
    if len(moved):
        _check_moved(out, f, moved)
    return out


def _check_moved(v, f, moved) -> None:
    """No faces near the ``moved`` vertices meet (exact check of the faces within two of their
    longest incident edges)."""
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    touch = np.isin(f, moved).any(axis=1)
    reach = 2 * float(np.linalg.norm(v[f[touch]] - v[f[touch]][:, [1, 2, 0]], axis=2).max())
    near = np.isfinite(cKDTree(v[moved]).query(v[f].mean(axis=1), distance_upper_bound=reach)[0])
    faces = np.flatnonzero(near | touch)
    if len(self_intersections(v, f[faces])):
        raise SeamMismatchError("a seam between two slabs does not match (a vertex moved onto it folds a face)")


def _successors(edges: np.ndarray) -> dict | None:
    """{a: b} for directed edges a -> b forming simple loops (None if a vertex leads twice)."""
    nxt = {}
    for a, b in edges.tolist():
        if a in nxt:
            return None
        nxt[a] = b
    return nxt
