"""BIQ by pulling the query ball back into the base slab: RangeFinder on the query side.

Node-group (i, j, k) is W**k ∘ V**j ∘ U**i ∘ N[0,0,0] (thesis §2.6, SPEC §3), and a similarity
keeps interference, so a query ball B meets node (i, j, k, n) iff W**-k B meets node
(i, j, 0, n) of the base slab, iff V**-j W**-k B meets node (i, 0, 0, n) of the U-row. Each step
is the §7.1.2 theorem on one steady row, with the *query* moved instead of the template:

1. k: the W-map extent of B against the hull of the base slab's node extents;
2. j: the V-map extent of W**-k B against the hull of the U-row's node extents;
3. i: the U-map extent of V**-j W**-k B against each template node's extent.

Nothing has to commute (the O(ūv̄) case of §7.3 without its per-W-row loop), and no group of
the lattice is evaluated: the plan holds the base slab's balls, ū v̄ groups, and their images
under the few powers W**d the beam-patterns reach. Exact tests run in the frame of W**-k,
against those tables.

Beams are found through their end nodes. A point of hull(ball(a, ra), ball(b, rb)) is
(1 - t) a' + t b' with a', b' in the balls, so it lies within max((|ab| + ra + rb) / 2, ra, rb)
of a or of b (the radius of the enclosing ball, ``enclosing_ball``); a query ball (y, ρ) that
meets a beam therefore has an end centre within ρ + R of y, R the largest such radius of the
slab's beams. The node search runs on node centres with that margin, and the candidate beams
are the beams at the nodes found, tested exactly.

Two forms give the same hits row for row (tested): the compiled one (``_rangefinder.pullback``,
all query balls in one call) and numpy (``_query_numpy``). The compiled one also skips clearance
look-ups that cannot matter: the distance to the slab's centres is 1-Lipschitz, and W**-k moves
the pulled centre by s**-k |W**-1 c - c| from k to k + 1, so after a clearance looked up at k0,
every k whose travelled path plus reach stays below it has no node within reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.elements import TOUCH_TOL, ball_beam_interfere, enclosing_ball
from ..model.lattice import Lattice
from .hits import BIQResults, split_hits
from .plans import cached
from .rangefinder import (
    MAX_WRAP_STEPS,
    RANGE_SLACK,
    ball_extents,
    cached_plan,
    candidate_range,
    compiled_fits,
    expand_ranges,
    frame_balls,
    packed_extents,
    packed_map,
    to_frame,
)

try:  # the compiled forms (setup.py, optional), as in rangefinder
    from . import _rangefinder as _compiled
except ImportError:  # not built (no C compiler): numpy
    _compiled = None

MAX_SLAB_BALLS = 1 << 21  # base-slab balls × W powers kept by one plan; larger lattices use lattice_hits
MARGIN = 1e-9  # relative widening of search radii: rounding never loses a touching element
MAX_CLEARANCE_CELLS = 1 << 20  # cells of the base slab's clearance grid
CLEARANCE_CELLS = 8  # clearances beyond this many cells are stored as this many


@dataclass
class _Plan:
    """Per-lattice tables (lattice frame, placement undone). ``maps``: the RowMaps of U, V, W;
    ``ext_w``/``ext_v``: hulls of the node-centre extents of the base slab / the U-row;
    ``ext_u``: per template node n, its centre's extents, arrays (nn,); ``w_inv``/``v_inv``:
    rows [S**-p]_{3x4} (count, 3, 4) and factors s**-p; ``slab``: {d: (centres (nu, nv, nn, 3),
    radii (nu, nv, nn))} of W**d applied to the base slab; ``node_r``: the largest node radius
    of the base slab; ``beam_r``: the largest enclosing radius R of its beams (in both the
    frames a candidate beam is tested in); ``grow``: the largest factor of W**k, k < nw."""

    maps: tuple
    ext_w: dict
    ext_v: dict
    ext_u: dict
    w_inv: tuple
    v_inv: tuple
    slab: dict
    node_r: float
    beam_r: float
    grow: float
    pats: np.ndarray  # (P, 5) n1, n2, di, dj, dk
    clearance: _Clearance
    kernel: tuple | None = None  # the compiled form's arrays (``_kernel_arrays``), None: the numpy form


@dataclass
class _Clearance:
    """A lower bound on the distance from any point to the base slab's node centres: a grid over
    their bounding box (corner ``lo``, cell ``size``, ``shape``, far corner ``hi``) holding per
    cell the distance from its centre to the nearest node centre minus the cell's half-diagonal,
    rounded down to whole ``step``s (one byte a cell: the grid stays in cache). For a point y and
    its projection y' onto the grid's box, every centre s in the box has |y - s|² >= |y - y'|² +
    |y' - s|² (the box is convex) and |y' - s| >= the bound of the cell holding y'."""

    lo: np.ndarray
    hi: np.ndarray
    size: float
    step: float
    shape: tuple
    bound: np.ndarray  # (cells,) uint8, C order: the bound in steps

    @classmethod
    def of(cls, pts: np.ndarray) -> _Clearance:
        from scipy.spatial import cKDTree  # noqa: PLC0415 - the plan only: keeps `import ple` light

        lo, hi = pts.min(axis=0), pts.max(axis=0)
        # sliding-midpoint splits and boxes not shrunk to the data: the same nearest distances,
        # found 2-7x faster for the grid's many centres far off a slab's sheet of nodes
        tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
        spacing = float(np.median(tree.query(pts[:min(len(pts), 4096)], k=2)[0][:, 1])) if len(pts) > 1 else 1.0
        ext = np.maximum(hi - lo, 1e-12)
        size = max(spacing, float(np.prod(ext) / MAX_CLEARANCE_CELLS) ** (1 / 3), float(ext.max()) / 4096, 1e-12)
        shape = tuple(int(x) for x in np.maximum(np.ceil(ext / size), 1))
        axes = [lo[a] + (np.arange(shape[a]) + 0.5) * size for a in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        half = 0.5 * size * np.sqrt(3.0)
        cap, step = CLEARANCE_CELLS * size, CLEARANCE_CELLS * size / 255
        dist = tree.query(centres, distance_upper_bound=cap)[0]  # inf beyond: a bound all the same
        bound = np.maximum(np.where(np.isfinite(dist), dist, cap) - half, 0.0)
        steps = np.minimum(np.floor(bound / step), 255)
        steps -= steps * step > bound  # rounding of the division never raises a bound
        return cls(lo, lo + np.array(shape) * size, size, step, shape, steps.astype(np.uint8))

    def lower_bound(self, y: np.ndarray) -> np.ndarray:
        """(m,) lower bounds on the distance from points y (m, 3) to the nearest node centre,
        computed as the compiled form does."""
        cell = np.floor((y - self.lo) / self.size)
        for a in range(3):  # clamped as floats: a far point's cell index never overflows
            np.clip(cell[:, a], 0, self.shape[a] - 1, out=cell[:, a])
        cell = cell.astype(np.int64)
        b = self.bound[(cell[:, 0] * self.shape[1] + cell[:, 1]) * self.shape[2] + cell[:, 2]] * self.step
        d = y - np.minimum(np.maximum(y, self.lo), self.hi)  # outside the box: its distance adds
        return np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2] + b * b)


def fits(lat: Lattice) -> bool:
    """Can ``query`` run on ``lat``: a steady lattice (no group map, steady radii) whose base
    slab, with the powers of W its beam-patterns reach, fits the plan's budget?"""
    if lat.group_map is not None or lat.radius_field is not None or lat.becots is not None:
        return False
    powers = 1 + 2 * len({b.dk for b in lat.beams if b.dk != 0})
    return lat.counts[0] * lat.counts[1] * len(lat.nodes) * powers <= MAX_SLAB_BALLS


def _hull(ext: dict) -> dict:
    """One interval per map enclosing every interval of ``ext`` (conservative: a union of
    intervals lies in its hull, also for the R-map's periodic wraps)."""
    return {key: (np.min(s), np.max(e)) for key, (s, e) in ext.items()}


def _inverse_rows(s, count: int):
    p = -np.arange(count, dtype=float)
    return np.ascontiguousarray(s.power_matrices(p)[:, :3]), s.factor ** p


def build(lat: Lattice) -> _Plan:
    """The plan of ``lat`` (see ``_Plan``): O(ū v̄ · nn) balls, computed once per lattice."""
    mu, mv, mw = cached_plan(lat).maps
    nu, nv, nw = lat.counts
    nn = len(lat.nodes)
    gi, gj = (x.reshape(-1) for x in np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij"))
    idx = np.stack([np.repeat(gi, nn), np.repeat(gj, nn), np.zeros(len(gi) * nn, np.int64),
                    np.tile(np.arange(nn), len(gi))], axis=1)
    c0, r0 = frame_balls(lat, idx)
    c0, r0 = c0.reshape(nu, nv, nn, 3), r0.reshape(nu, nv, nn)
    zero = np.zeros(1)
    ext_w = _hull(ball_extents(mw, c0.reshape(-1, 3), zero))
    ext_v = _hull(ball_extents(mv, c0[:, 0].reshape(-1, 3), zero))
    ext_u = ball_extents(mu, c0[0, 0], np.zeros(nn))
    pats = np.array([(b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams], dtype=np.int64).reshape(-1, 5)
    slab = {0: (c0, r0)}
    for d in {int(x) for x in pats[:, 4]} | {-int(x) for x in pats[:, 4]}:
        if d not in slab:
            m = lat.W.power_matrices([float(d)])[0]
            slab[d] = (c0 @ m[:3, :3].T + m[:3, 3], r0 * lat.W.factor ** d)
    beam_r = 0.0
    for n1, n2, di, dj, dk in pats:  # every beam of the base slab, from- and to-end frames
        i0, i1 = max(0, -di), min(nu, nu - di)
        j0, j1 = max(0, -dj), min(nv, nv - dj)
        if i1 <= i0 or j1 <= j0:
            continue
        for da, db in ((0, dk), (-dk, 0)):
            ca, ra = slab[da][0][i0:i1, j0:j1, n1], slab[da][1][i0:i1, j0:j1, n1]
            ends = (slice(i0 + di, i1 + di), slice(j0 + dj, j1 + dj), n2)
            cb, rb = slab[db][0][ends], slab[db][1][ends]
            beam_r = max(beam_r, float(np.max(np.maximum(enclosing_ball(ca, ra, cb, rb)[1], np.maximum(ra, rb)))))
    fw = lat.W.factor
    pl = _Plan((mu, mv, mw), ext_w, ext_v, ext_u, _inverse_rows(lat.W, nw), _inverse_rows(lat.V, nv), slab,
               float(r0.max()), beam_r, max(1.0, fw ** (nw - 1)), pats, _Clearance.of(c0.reshape(-1, 3)))
    if compiled_fits(lat):
        pl.kernel = _kernel_arrays(pl)
    return pl


def _kernel_arrays(pl: _Plan) -> tuple:
    """The plan as the compiled form reads it: maps, extents, inverse powers of W and V, the
    slab under each W power (balls (S, nu, nv, nn, 4)) with a slot per power, the clearance
    bounds and the beam-patterns."""
    reach = max(abs(d) for d in pl.slab)
    slot = np.full(2 * reach + 1, -1, np.int64)
    balls = []
    for s, (d, (c, r)) in enumerate(sorted(pl.slab.items())):
        slot[d + reach] = s
        balls.append(np.concatenate([c, r[..., None]], axis=-1))
    nn = pl.slab[0][1].shape[2]
    (wm, wf), (vm, vf) = pl.w_inv, pl.v_inv
    return (np.concatenate([packed_map(m) for m in pl.maps]), packed_extents(pl.ext_w, 1),
            packed_extents(pl.ext_v, 1), packed_extents(pl.ext_u, nn), np.ascontiguousarray(wm.reshape(-1, 12)),
            np.ascontiguousarray(wf, dtype=float), np.ascontiguousarray(vm.reshape(-1, 12)),
            np.ascontiguousarray(vf, dtype=float),
            np.ascontiguousarray(np.stack(balls)), slot, pl.clearance.bound,
            np.ascontiguousarray(pl.pats, dtype=np.int64))


def cached_pullback(lat: Lattice) -> _Plan:
    return cached(lat, "pullback", build)


def _pull(rows: tuple, p: np.ndarray, x: np.ndarray, r: np.ndarray):
    """Apply S**-p (rows from ``_inverse_rows``) to balls (x (m, 3), r (m,)), each coordinate
    summed ((m0 x0 + m1 x1) + m2 x2) + m3 as the compiled form does."""
    m, f = rows[0][p], rows[1][p]
    return (m[:, :, 0] * x[:, None, 0] + m[:, :, 1] * x[:, None, 1] + m[:, :, 2] * x[:, None, 2] + m[:, :, 3],
            r * f)


def query(lat: Lattice, c: np.ndarray, r: np.ndarray, beams: bool = True) -> BIQResults:
    """Per query ball (c (q, 3), r (q,), world coordinates), its node hits and, unless ``beams``
    is False, its beam hits (path "pullback"): the compiled form when it is built and its keys
    fit in int64, else the numpy form (the same hits, tested). Requires ``fits(lat)``."""
    pl = cached_pullback(lat)
    if pl.kernel is None:
        return split_hits(len(c), *_query_numpy(lat, c, r, beams), "pullback")
    qc, qr = to_frame(lat, c, r)
    h = _margin(pl, beams)
    cl = pl.clearance
    params = np.array([h, h * pl.grow, pl.beam_r * (1 + MARGIN), 1 + MARGIN, TOUCH_TOL, RANGE_SLACK, MAX_WRAP_STEPS,
                       *cl.lo, *cl.hi, cl.size, cl.step, *cl.shape])
    nodes, node_ends, beam_rows, beam_ends = _compiled.pullback(
        (*lat.counts, len(lat.nodes)), *pl.kernel, params, np.ascontiguousarray(qc, dtype=float),
        np.ascontiguousarray(qr, dtype=float), beams)
    as_rows = lambda b: np.frombuffer(b, np.int64).reshape(-1, 4)  # noqa: E731
    return BIQResults(as_rows(nodes), np.frombuffer(node_ends, np.int64), as_rows(beam_rows),
                      np.frombuffer(beam_ends, np.int64), "pullback")


def _margin(pl: _Plan, beams: bool) -> float:
    """Slab-frame margin around node centres: the largest node radius, or with beams the
    largest enclosing radius of a beam when that is larger."""
    return max(pl.node_r, pl.beam_r if beams and len(pl.pats) else 0.0)


def _query_numpy(lat: Lattice, c: np.ndarray, r: np.ndarray, beams: bool = True):
    """The numpy form of ``query``: hits (qid, i, j, k, n) of nodes and (qid, i, j, k, pattern)
    of beams (empty when ``beams`` is False), int64 arrays (N, 5), unsorted."""
    pl = cached_pullback(lat)
    mu, mv, mw = pl.maps
    nu, nv, nw = lat.counts
    nn = len(lat.nodes)
    qc, qr = to_frame(lat, c, r)
    h = _margin(pl, beams)
    # 1. k: W-map of the query, widened by the margin at the largest scale of W**k
    lo, hi = candidate_range(mw, pl.ext_w, ball_extents(mw, qc, (qr + h * pl.grow) * (1 + MARGIN)), (len(qc),))
    qid, k = expand_ranges(lo, hi)
    y, rho = _pull(pl.w_inv, k, qc[qid], qr[qid])  # the query in the base slab's frame
    near = pl.clearance.lower_bound(y) <= (rho + h) * (1 + MARGIN)  # W**-k B reaches the slab at all
    qid, k, y, rho = qid[near], k[near], y[near], rho[near]
    # 2. j: V-map of the pulled query against the U-row
    lo, hi = candidate_range(mv, pl.ext_v, ball_extents(mv, y, (rho + h) * (1 + MARGIN)), (len(y),))
    row, j = expand_ranges(lo, hi)
    z, zr = _pull(pl.v_inv, j, y[row], (rho[row] + h) * (1 + MARGIN))
    # 3. i: U-map of the twice pulled query against each template node
    lo, hi = candidate_range(mu, {key: (s[None], e[None]) for key, (s, e) in pl.ext_u.items()},
                             {key: (s[:, None], e[:, None]) for key, (s, e) in ball_extents(mu, z, zr).items()},
                             (len(z), nn))
    cand, i = expand_ranges(lo.reshape(-1), hi.reshape(-1))
    r2, n = cand // nn, cand % nn
    s, jj = row[r2], j[r2]  # s: rows of (y, rho), the query in the base slab's frame
    c0, r0 = pl.slab[0]
    d = c0[i, jj, n] - y[s]
    dist2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    rq = rho[s]
    rr = rq + r0[i, jj, n]
    hit = dist2 <= rr * rr * (1 + TOUCH_TOL) + TOUCH_TOL * TOUCH_TOL
    node_hits = np.stack([qid[s[hit]], i[hit], jj[hit], k[s[hit]], n[hit]], axis=1)
    if not beams or not len(pl.pats):
        return node_hits, np.zeros((0, 5), np.int64)
    reach = rq + pl.beam_r * (1 + MARGIN)
    near = dist2 <= reach * reach
    return node_hits, _beam_hits(pl, lat.counts, qid[s[near]], i[near], jj[near], k[s[near]], n[near],
                                 y[s[near]], rq[near])


def _beam_hits(pl: _Plan, counts, qid, i, j, k, n, y, rho) -> np.ndarray:
    """Exact tests of the beams at candidate nodes (i, j, k, n) (arrays (m,)) against the
    pulled queries (y (m, 3), rho (m,)) in the frame of W**-k; rows (qid, i, j, k, pattern)."""
    nu, nv, nw = counts
    parts = []
    for p, (n1, n2, di, dj, dk) in enumerate(pl.pats):
        for at_from in (True, False):
            sel = np.flatnonzero(n == (n1 if at_from else n2))
            if not len(sel):
                continue
            a_i, a_j, a_k = (i[sel], j[sel], k[sel]) if at_from else (i[sel] - di, j[sel] - dj, k[sel] - dk)
            ok = ((a_i >= 0) & (a_i + di >= 0) & (a_i < nu) & (a_i + di < nu) & (a_j >= 0) & (a_j + dj >= 0)
                  & (a_j < nv) & (a_j + dj < nv) & (a_k >= 0) & (a_k + dk >= 0) & (a_k < nw) & (a_k + dk < nw))
            sel, a_i, a_j, a_k = sel[ok], a_i[ok], a_j[ok], a_k[ok]
            da, db = (0, dk) if at_from else (-dk, 0)  # the frame of the node found is W**-k
            ca, ra = pl.slab[da][0][a_i, a_j, n1], pl.slab[da][1][a_i, a_j, n1]
            cb, rb = pl.slab[db][0][a_i + di, a_j + dj, n2], pl.slab[db][1][a_i + di, a_j + dj, n2]
            hit = ball_beam_interfere(y[sel], rho[sel], ca, ra, cb, rb)
            parts.append(np.stack([qid[sel][hit], a_i[hit], a_j[hit], a_k[hit], np.full(int(hit.sum()), p)], axis=1))
    hits = np.concatenate(parts) if parts else np.zeros((0, 5), np.int64)
    key = (((hits[:, 0] * nu + hits[:, 1]) * nv + hits[:, 2]) * nw + hits[:, 3]) * len(pl.pats) + hits[:, 4]
    _, first = np.unique(key, return_index=True)  # a beam found from both of its ends counts once
    return hits[first]
