"""RangeFinder: candidate index ranges of steady rows that may interfere with query balls.

Thesis §7.1–7.3 (and the RangeFinder paper, 000_). A steady row R[k] = S**k ∘ R[0] is
queried through *normalized maps* M with M(S X) = M(X) + 1 (§7.1.2): if the template
extent (image of R[0] under M) is [s0, e0] and the query extent [sq, eq], only
k in [ceil(sq - e0), floor(eq - s0)] can interfere. S is split by its canonical
decomposition (§7.1.1) into a rotation R about its axis and a translation T along it
(screw) or a dilation D about a fixed point on it (swirl); each primitive has its map:

- T-map (§7.1.3): M(X) = (X - O)·a with a·t = 1 for the slide t (a = t/|t|² in the thesis;
  when U, V and W are all translations we use the dual basis, so that each map is
  invariant under the other two directions);
- D-map (§7.1.4): M(X) = log_d |X - F|;
- R-map (§7.1.5): M(X) = angle about the axis / θ, periodic with period 2π/|θ|, one
  candidate interval per wrap; rows that wrap more than once get, inside the range of the
  other primitive, the hull of the wraps' intervals (§7.1.6 intersection).

Ball extents follow §7.1.3–7.1.5, beam extents §7.2. A map whose primitive is numerically
degenerate is dropped, which only widens ranges (always conservative). Every range is
widened by ``RANGE_SLACK`` index units so that rounding never loses a touching element;
exact element tests decide afterwards.

BIQ on a lattice (§7.3) uses one of three paths, detected from the lattice (§7.3.1):
``"1"`` (U, V, W commute and each map is invariant under the other two directions: one
range per direction), ``"u"`` (the same for V and W only: per U index i) and ``"uv"``
(general: per W-row (i, j)); the "uv" path first culls blocks of W-rows through the
RangeFinder ranges of their bounding balls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..algebra.elements import TOUCH_TOL, ball_ball_interfere, ball_beam_interfere, beam_distance, enclosing_ball
from ..algebra.similarity import Similarity, commute
from ..errors import PleError, echo
from ..model.lattice import Lattice
from .plans import cached

RANGE_SLACK = 1e-7  # index units added on both sides of every candidate range
DEGENERATE = 1e-9  # |log d|, |θ| or slide below this: the primitive's map is dropped
INVARIANCE_TOL = 1e-9  # normalized units, for the §7.3.1 conditions
MAX_WRAP_STEPS = 64
BLOCK = 8  # W-rows per block side in the "uv" path's culling level
QUERY_BATCH = 1 << 15
MAX_VW_TABLE = 1 << 18  # largest V×W table of the O(ū) path kept per lattice
MAX_POWER_TABLE = 1 << 20  # longest direction whose powers are cached for the exact tests
MAX_KEY = 1 << 62  # hit keys ((i nv + j) nw + k) · max(nn, patterns) of the compiled forms stay below

try:  # the compiled forms (setup.py, optional): every query at once, the numpy forms' hits
    from . import _rangefinder as _compiled
except ImportError:  # not built (no C compiler): numpy
    _compiled = None


# ----- normalized maps of one incremental similarity -----------------------------------------
@dataclass(frozen=True)
class RowMap:
    """Normalized maps of a steady row with ``count`` elements (canonical decomposition §7.1.1).

    ``a`` (3,) and ``origin``: T-map, or None; ``log_d`` and ``fixed``: D-map, or None;
    ``theta``, ``axis``, ``point``, ``ref``: R-map, or None (θ = None)."""

    count: int
    a: np.ndarray | None = None
    origin: np.ndarray | None = None
    log_d: float | None = None
    fixed: np.ndarray | None = None
    theta: float | None = None
    axis: np.ndarray | None = None
    point: np.ndarray | None = None
    ref: np.ndarray | None = None

    @property
    def period(self) -> float:
        return 2 * math.pi / abs(self.theta)


def row_map(s: Similarity, count: int, a: np.ndarray | None = None) -> RowMap:
    """Maps of S (a row of ``count``); ``a`` overrides the T-map vector (must satisfy a·t = 1)."""
    if count <= 1:
        return RowMap(count)
    kw: dict = {}
    axis, point = s.r, s.p
    if s.factor == 1.0 and abs(s.distance) > DEGENERATE:  # screw / translation: slide along the axis
        kw["a"] = axis / s.distance if a is None else np.asarray(a, float)
        kw["origin"] = point
    if abs(math.log(s.factor)) > DEGENERATE:  # swirl / scaling: dilation about F = point
        kw["log_d"] = math.log(s.factor)
        kw["fixed"] = point
    if abs(s.angle) > DEGENERATE and abs(s.angle) < 1e6:
        ref = np.cross(axis, [1.0, 0.0, 0.0])
        if np.linalg.norm(ref) < 0.5:
            ref = np.cross(axis, [0.0, 1.0, 0.0])
        kw.update(theta=float(s.angle), axis=axis, point=point, ref=ref / np.linalg.norm(ref))
    return RowMap(count, **kw)


def _r_frame(rm: RowMap, c: np.ndarray):
    """Perpendicular offset from the axis (…, 3), its length and the angle about the axis."""
    rel = c - rm.point
    perp = rel - (rel @ rm.axis)[..., None] * rm.axis
    dist = np.linalg.norm(perp, axis=-1)
    side = np.cross(rm.axis, rm.ref)
    phi = np.arctan2(perp @ side, perp @ rm.ref)
    return perp, dist, phi


def map_points(rm: RowMap, x: np.ndarray) -> dict:
    """Images of points (…, 3) under each map (R-map in its branch 0)."""
    out = {}
    if rm.a is not None:
        out["t"] = (x - rm.origin) @ rm.a
    if rm.log_d is not None:
        with np.errstate(divide="ignore"):
            out["d"] = np.log(np.linalg.norm(x - rm.fixed, axis=-1)) / rm.log_d
    if rm.theta is not None:
        out["r"] = _r_frame(rm, x)[2] / rm.theta
    return out


def ball_extents(rm: RowMap, c, r) -> dict:
    """Extents {"t"|"d"|"r": (s, e)} of balls (c (…, 3), r (…)) under each map (§7.1.3–7.1.5)."""
    c, r = np.asarray(c, float), np.asarray(r, float)
    out = {}
    if rm.a is not None:
        m = c @ rm.a
        m -= rm.origin @ rm.a
        w = r * np.linalg.norm(rm.a)
        out["t"] = (m - w, m + w)
    if rm.log_d is not None:
        dist = np.linalg.norm(c - rm.fixed, axis=-1)
        out["d"] = _d_extent(rm, dist - r, dist + r)
    if rm.theta is not None:
        _, dist, phi = _r_frame(rm, c)
        m = phi / rm.theta
        inside = dist <= r  # special case: the axis meets the ball, full range
        h = np.arcsin(np.clip(r / np.where(inside, 1.0, dist), 0, 1)) / abs(rm.theta)
        out["r"] = (np.where(inside, -np.inf, m - h), np.where(inside, np.inf, m + h))
    return out


def _d_extent(rm: RowMap, near, far):
    """D-map extent of the shell near <= |X - F| <= far (near <= 0: F inside, ∓∞)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ln_near = np.where(near > 0, np.log(np.maximum(near, 1e-300)), -np.inf)
        a, b = ln_near / rm.log_d, np.log(far) / rm.log_d
    return np.minimum(a, b), np.maximum(a, b)


def beam_extents(rm: RowMap, ca, ra, cb, rb) -> dict:
    """Extents of cone-beams hull(ball(ca, ra), ball(cb, rb)) under each map (§7.2)."""
    ca, cb = np.asarray(ca, float), np.asarray(cb, float)
    ra, rb = np.asarray(ra, float), np.asarray(rb, float)
    ea, eb = ball_extents(rm, ca, ra), ball_extents(rm, cb, rb)
    out = {}
    if "t" in ea:  # the extreme points along the slide lie on the end balls
        out["t"] = (np.minimum(ea["t"][0], eb["t"][0]), np.maximum(ea["t"][1], eb["t"][1]))
    if "d" in ea:  # the point nearest F may lie on the cone: distance f from F to the beam
        f = beam_distance(rm.fixed, ca, ra, cb, rb)
        far = np.maximum(np.linalg.norm(ca - rm.fixed, axis=-1) + ra, np.linalg.norm(cb - rm.fixed, axis=-1) + rb)
        near = np.minimum(f, np.minimum(np.linalg.norm(ca - rm.fixed, axis=-1) - ra,
                                        np.linalg.norm(cb - rm.fixed, axis=-1) - rb))
        out["d"] = _d_extent(rm, near, far)
    if "r" in ea:
        pa, da, phia = _r_frame(rm, ca)
        pb, db, phib = _r_frame(rm, cb)
        # special case: the axis meets the beam iff its projection (the 2D hull of the two
        # projected disks) contains the axis point: full range
        meets = beam_distance(np.zeros(3), pa, ra, pb, rb) <= 0
        delta = np.angle(np.exp(1j * (phib - phia)))  # angle from C_A to C_B about the axis, (-π, π]
        ma = phia / rm.theta
        ha = np.arcsin(np.clip(ra / np.where(da > 0, da, 1.0), 0, 1)) / abs(rm.theta)
        hb = np.arcsin(np.clip(rb / np.where(db > 0, db, 1.0), 0, 1)) / abs(rm.theta)
        y = ma + delta / rm.theta
        s = np.minimum(ma - ha, y - hb)
        e = np.maximum(ma + ha, y + hb)
        out["r"] = (np.where(meets, -np.inf, s), np.where(meets, np.inf, e))
    return out


def candidate_range(rm: RowMap, tmpl: dict, q: dict, shape: tuple = ()):
    """Integer candidate range [lo, hi] (arrays of ``shape``; empty when hi < lo) of a row,
    given template and query extents that broadcast to ``shape`` (§7.1.2 theorem, §7.1.6)."""
    shape = np.broadcast_shapes(shape, *[np.shape(x[0]) for x in list(tmpl.values()) + list(q.values())])
    lo = np.zeros(shape)
    hi = np.full(shape, float(rm.count - 1))
    # fmax/fmin ignore NaN (no information from that map: the range stays as it was)
    with np.errstate(invalid="ignore"):
        for key in ("t", "d"):
            if key in tmpl:
                x = np.subtract(q[key][0], tmpl[key][1])
                x -= RANGE_SLACK
                np.fmax(lo, np.ceil(x, out=x), out=lo)
                x = np.subtract(q[key][1], tmpl[key][0])
                x += RANGE_SLACK
                np.fmin(hi, np.floor(x, out=x), out=hi)
        if "r" in tmpl:
            lo, hi = _rotation_range(rm, q["r"][0] - tmpl["r"][1] - RANGE_SLACK,
                                     q["r"][1] - tmpl["r"][0] + RANGE_SLACK, lo, hi)
    np.fmin(lo, rm.count, out=lo)
    np.fmax(hi, -1, out=hi)
    return lo.astype(np.int64), hi.astype(np.int64)


def _rotation_range(rm: RowMap, alpha, beta, lo, hi):
    """Narrow [lo, hi] to the hull of its integers lying in some wrap [α + mP, β + mP] (§7.1.5)."""
    p = rm.period
    alpha, beta = np.broadcast_to(alpha, lo.shape), np.broadcast_to(beta, lo.shape)
    active = np.isfinite(alpha) & np.isfinite(beta) & (beta - alpha < p - 1e-12) & (lo <= hi)
    if not active.any():
        return lo, hi
    a, b, l0, h0 = alpha[active], beta[active], lo[active], hi[active]
    # lowest candidate: first wrap whose end reaches l0, then step wraps until one holds an integer
    m = np.ceil((l0 - b) / p)
    new_lo = np.full_like(l0, np.inf)
    todo = np.ones(len(a), bool)
    for _ in range(MAX_WRAP_STEPS):
        cand = np.maximum(l0, np.ceil(a + m * p))
        ok = todo & (cand <= np.floor(b + m * p))
        new_lo[ok] = cand[ok]
        todo &= ~ok & (cand <= h0)
        if not todo.any():
            break
        m += 1
    new_lo[todo] = l0[todo]  # unresolved after many wraps: keep the conservative bound
    m = np.floor((h0 - a) / p)
    new_hi = np.full_like(h0, -np.inf)
    todo = np.ones(len(a), bool)
    for _ in range(MAX_WRAP_STEPS):
        cand = np.minimum(h0, np.floor(b + m * p))
        ok = todo & (cand >= np.ceil(a + m * p))
        new_hi[ok] = cand[ok]
        todo &= ~ok & (cand >= l0)
        if not todo.any():
            break
        m -= 1
    new_hi[todo] = h0[todo]
    lo, hi = lo.copy(), hi.copy()
    empty = ~np.isfinite(new_lo) | ~np.isfinite(new_hi)
    new_lo[empty], new_hi[empty] = 1.0, 0.0
    lo[active], hi[active] = new_lo, new_hi
    return lo, hi


def row_candidates(s: Similarity, count: int, c0, r0, qc, qr):
    """Candidate range [lo, hi] of a steady row of balls S**k (c0, r0), k < count, for query
    balls (qc, qr) — the RangeFinder of one row, broadcasting over queries."""
    rm = row_map(s, count)
    # one range per query ball, even when the row map has no extents (e.g. one element)
    return candidate_range(rm, ball_extents(rm, c0, r0), ball_extents(rm, qc, qr), np.shape(np.asarray(qr)))


# ----- lattice structure: paths of §7.3.1 ------------------------------------------------------
@dataclass
class _Plan:
    path: str
    maps: tuple  # RowMaps of U, V, W
    elements: int
    tables: dict = field(default_factory=dict)  # template extents, filled on first use
    forced: dict = field(default_factory=dict)  # plans of slower paths forced on this lattice, by path


def _active(lat: Lattice) -> list[bool]:
    return [c > 1 for c in lat.counts]


def _invariant(rm: RowMap, s: Similarity, pts: np.ndarray) -> bool:
    """Is every map of ``rm`` unchanged by applying ``s`` (§7.3.1 conditions 2–5)?"""
    before, after = map_points(rm, pts), map_points(rm, s.apply_points(pts))
    for key, v in before.items():
        diff = after[key] - v
        if key == "r":  # angles: compare modulo one turn
            diff = np.angle(np.exp(1j * diff * rm.theta)) / rm.theta
        if not np.all(np.abs(diff) <= INVARIANCE_TOL * (1 + np.abs(v))):
            return False
    return True


def _sample_points(lat: Lattice) -> np.ndarray:
    rng = np.random.default_rng(12345)
    c = frame_balls(lat, np.array([[0, 0, 0, n] for n in range(len(lat.nodes))]))[0]
    scale = max(1.0, float(np.abs(c).max()))
    return np.concatenate([c, c[0] + rng.normal(size=(12, 3)) * scale])


def plan(lat: Lattice) -> _Plan:
    """Detect the path (§7.3.1) and build the maps of U, V, W in the lattice frame."""
    act = _active(lat)
    sims = (lat.U, lat.V, lat.W)
    a_vecs: list = [None, None, None]
    trans = [i for i in range(3) if act[i]]
    if trans and all(sims[i].kind == "translation" for i in trans):
        t = np.array([sims[i].distance * sims[i].r for i in trans])
        gram = t @ t.T
        if abs(np.linalg.det(gram)) > 1e-12 * np.prod(np.diag(gram)):
            dual = np.linalg.solve(gram, t)  # rows a_x with a_x · t_y = δ_xy
            for row, i in enumerate(trans):
                a_vecs[i] = dual[row]
    maps = tuple(row_map(s, c, a) for s, c, a in zip(sims, lat.counts, a_vecs))
    pts = _sample_points(lat)

    def ok(x: int, y: int) -> bool:
        if not (act[x] and act[y]):
            return True
        return (commute(sims[x], sims[y]) and _invariant(maps[x], sims[y], pts)
                and _invariant(maps[y], sims[x], pts))

    elements = len(lat.nodes) + len(lat.beams)
    if ok(1, 2) and ok(0, 1) and ok(0, 2):
        return _Plan("1", maps, elements)
    if ok(1, 2):
        return _Plan("u", maps, elements)
    return _Plan("uv", maps, elements)


# ----- element geometry in the lattice frame (placement G undone) -------------------------------
def frame_balls(lat: Lattice, index: np.ndarray):
    c, r = lat.node_balls(index)
    g = lat.placement
    if g.kind == "identity":
        return c, r
    return g.inverse().apply_points(c), r / g.factor


def _pattern_table(lat: Lattice) -> np.ndarray:
    return np.array([(b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams], dtype=np.int64).reshape(-1, 5)


def _element_extents(lat: Lattice, rm: RowMap, gi, gj, gk):
    """Extents of every element of groups (gi, gj, gk) (arrays (G,)) under one map: dict of
    (s, e) arrays shaped (G, E), nodes first then beam-patterns; also bounding balls."""
    nn, pats = len(lat.nodes), _pattern_table(lat)
    g = len(gi)
    idx = np.stack([np.repeat(gi, nn), np.repeat(gj, nn), np.repeat(gk, nn), np.tile(np.arange(nn), g)], axis=1)
    nc, nr = frame_balls(lat, idx)
    nc, nr = nc.reshape(g, nn, 3), nr.reshape(g, nn)
    ext = {key: (s.reshape(g, nn), e.reshape(g, nn)) for key, (s, e) in ball_extents(rm, nc, nr).items()}
    centers, radii = [nc], [nr]
    if len(pats):
        ca, ra = nc[:, pats[:, 0]], nr[:, pats[:, 0]]
        np_ = len(pats)
        end = np.stack([np.repeat(gi, np_) + np.tile(pats[:, 2], g), np.repeat(gj, np_) + np.tile(pats[:, 3], g),
                        np.repeat(gk, np_) + np.tile(pats[:, 4], g), np.tile(pats[:, 1], g)], axis=1)
        cb, rb = frame_balls(lat, end)
        cb, rb = cb.reshape(g, np_, 3), rb.reshape(g, np_)
        bext = beam_extents(rm, ca, ra, cb, rb)
        ext = {key: (np.concatenate([ext[key][0], bext[key][0]], axis=1),
                     np.concatenate([ext[key][1], bext[key][1]], axis=1)) for key in ext}
        bc, br = enclosing_ball(ca, ra, cb, rb)
        centers.append(bc)
        radii.append(br)
    return ext, np.concatenate(centers, axis=1), np.concatenate(radii, axis=1)


def _take(ext: dict, rows, cols=None) -> dict:
    if cols is None:
        return {k: (s[rows], e[rows]) for k, (s, e) in ext.items()}
    return {k: (s[rows, cols], e[rows, cols]) for k, (s, e) in ext.items()}


def expand_ranges(lo: np.ndarray, hi: np.ndarray):
    """For ranges [lo, hi] per row: (row index, value) of every integer inside, as arrays."""
    n = np.maximum(hi - lo + 1, 0)
    rows = np.repeat(np.arange(len(lo)), n)
    start = np.cumsum(n) - n
    return rows, lo[rows] + (np.arange(int(n.sum())) - start[rows])


# ----- candidate generation per path ------------------------------------------------------------
def _group_ball(bc: np.ndarray, br: np.ndarray):
    """A ball enclosing element balls (..., E, 3), (..., E): centre the mean of their centres."""
    gc = bc.mean(axis=-2)
    return gc, (np.linalg.norm(bc - gc[..., None, :], axis=-1) + br).max(axis=-1)


def _templates(lat: Lattice, pl: _Plan) -> dict:
    """Template extents of the plan's path, computed once per lattice (cached on the plan)."""
    if pl.tables:
        return pl.tables
    mu, mv, mw = pl.maps
    nu, nv, _ = lat.counts
    t = pl.tables
    if pl.path == "1":
        z = np.zeros(1, np.int64)
        t["ext"] = [_element_extents(lat, m, z, z, z)[0] for m in pl.maps]
    elif pl.path == "u":
        gi, z = np.arange(nu), np.zeros(nu, np.int64)
        t["ext_v"], bc, br = _element_extents(lat, mv, gi, z, z)  # (nu, E)
        t["ext_w"] = _element_extents(lat, mw, gi, z, z)[0]
        t["gc"], t["gr"] = _group_ball(bc, br)
        t["gext_v"], t["gext_w"] = ball_extents(mv, t["gc"], t["gr"]), ball_extents(mw, t["gc"], t["gr"])
        axis = _invariant_axis(lat, pl)
        if axis is not None:  # distance to the axis is kept by V and W: bound each i-sheet
            rho = _axis_distance(axis, t["gc"])
            t["axis"], t["rho"] = axis, (np.maximum(rho - t["gr"], 0.0), rho + t["gr"])
        nw = lat.counts[2]
        if nv * nw <= MAX_VW_TABLE:  # W**k V**j (they commute), as 3x4 rows indexed j * nw + k
            vw = lat.W.power_matrices(np.arange(nw))[None, :, :3] @ lat.V.power_matrices(np.arange(nv))[:, None]
            t["vw"] = np.ascontiguousarray(vw[:, :, :3].reshape(nv * nw, 3, 4))
    else:
        gi, gj = (x.reshape(-1) for x in np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij"))
        t["ext"], bc, br = _element_extents(lat, mw, gi, gj, np.zeros_like(gi))  # (nu*nv, E)
        t["gc"], t["gr"] = _group_ball(bc, br)
        t["gext"] = ball_extents(mw, t["gc"], t["gr"])
        # blocks of BLOCK × BLOCK W-rows, each with a ball enclosing its group balls
        nbj = (nv + BLOCK - 1) // BLOCK
        block = (gi // BLOCK) * nbj + gj // BLOCK
        nb = int(block.max()) + 1
        cnt = np.bincount(block, minlength=nb)
        kc = np.stack([np.bincount(block, t["gc"][:, d], minlength=nb) for d in range(3)], axis=1) / cnt[:, None]
        kr = np.zeros(nb)
        np.maximum.at(kr, block, np.linalg.norm(t["gc"] - kc[block], axis=1) + t["gr"])
        t.update(kc=kc, kr=kr, kext=ball_extents(mw, kc, kr), order=np.argsort(block, kind="stable"),
                 starts=np.concatenate([[0], np.cumsum(cnt)]))
    return t


def _q(ext: dict, idx=None, expand: int = 0) -> dict:
    """Select query extents (by index array) and/or add trailing axes for broadcasting."""
    out = {}
    for key, (s, e) in ext.items():
        if idx is not None:
            s, e = s[idx], e[idx]
        out[key] = (s.reshape(s.shape + (1,) * expand), e.reshape(e.shape + (1,) * expand))
    return out


def _candidates(lat: Lattice, pl: _Plan, qc: np.ndarray, qr: np.ndarray) -> np.ndarray:
    """Candidate (qid, i, j, k, element) rows (int64 (N, 5)) for queries in the lattice frame."""
    t = _templates(lat, pl)
    mu, mv, mw = pl.maps
    nq, ne = len(qc), pl.elements
    if pl.path == "1":  # §7.3.1 O(1): one range per direction from the template group
        ranges = []
        for d, m in enumerate(pl.maps):
            lo, hi = candidate_range(m, t["ext"][d], _q(ball_extents(m, qc, qr), expand=1), (nq, ne))
            ranges.append((lo.reshape(-1), hi.reshape(-1)))
        return _boxes(ranges, np.repeat(np.arange(nq), ne), np.tile(np.arange(ne), nq))
    if pl.path == "u":
        return _u_candidates(lat, t, pl, qc, qr)
    return _uv_candidates(lat, t, pl, qc, qr)


def _u_candidates(lat: Lattice, t: dict, pl: _Plan, qc, qr) -> np.ndarray:
    """§7.3.1 O(ū): per U index i, a V-range and a W-range of the group ball of (i, 0, 0);
    the group ball moved by V**j W**k is tested, then each element's own ranges."""
    _, mv, mw = pl.maps
    nq, nu, ne = len(qc), lat.counts[0], pl.elements
    qv, qw = ball_extents(mv, qc, qr), ball_extents(mw, qc, qr)
    jlo, jhi = candidate_range(mv, t["gext_v"], _q(qv, expand=1), (nq, nu))
    klo, khi = candidate_range(mw, t["gext_w"], _q(qw, expand=1), (nq, nu))
    if "axis" in t:  # i-sheets whose distance band to the common axis misses the query's
        rho, qrr = _axis_distance(t["axis"], qc)[:, None], qr[:, None] * (1 + 1e-9) + 1e-12
        miss = (rho + qrr < t["rho"][0][None] * (1 - 1e-9)) | (rho - qrr > t["rho"][1][None] * (1 + 1e-9))
        jhi = np.where(miss, -1, jhi)
    ii = np.tile(np.arange(nu), nq)
    g = _boxes([(ii, ii), (jlo.reshape(-1), jhi.reshape(-1)), (klo.reshape(-1), khi.reshape(-1))],
               np.repeat(np.arange(nq), nu), np.zeros(nq * nu, np.int64))
    gc, gr = t["gc"][g[:, 1]], t["gr"][g[:, 1]]
    if "vw" in t:
        m = t["vw"][g[:, 2] * lat.counts[2] + g[:, 3]]
        moved = (m[:, :, :3] @ gc[:, :, None])[:, :, 0] + m[:, :, 3]
        scale = lat.V.factor ** g[:, 2].astype(float) * lat.W.factor ** g[:, 3].astype(float)
        hit = ball_ball_interfere(moved, gr * scale * (1 + 1e-9) + 1e-12, qc[g[:, 0]], qr[g[:, 0]])
    else:
        hit = _moved_ball_hits([(lat.V, g[:, 2]), (lat.W, g[:, 3])], gc, gr, qc[g[:, 0]], qr[g[:, 0]])
    g = g[hit]
    el = np.tile(np.arange(ne), len(g))
    g = np.repeat(g, ne, axis=0)
    g[:, 4] = el
    for m, qe, col, key in ((mv, qv, 2, "ext_v"), (mw, qw, 3, "ext_w")):
        lo, hi = candidate_range(m, _take(t[key], g[:, 1], el), _q(qe, g[:, 0]), (len(g),))
        keep = (g[:, col] >= lo) & (g[:, col] <= hi)
        g, el = g[keep], el[keep]
    return g


def _axis_distance(axis, x: np.ndarray) -> np.ndarray:
    point, direction = axis
    rel = x - point
    return np.linalg.norm(rel - (rel @ direction)[..., None] * direction, axis=-1)


def _invariant_axis(lat: Lattice, pl: _Plan):
    """A line whose distance function both V and W preserve (e.g. V turns about it and W
    slides along it), or None; checked on sample points. Used to cull U indices in the
    O(ū) path: every element of sheet i stays within its group ball's distance band."""
    pts = _sample_points(lat)
    for m in pl.maps[1:]:
        if m.theta is None:
            continue
        axis = (m.point, m.axis)
        before = _axis_distance(axis, pts)
        if all(np.allclose(_axis_distance(axis, s.apply_points(pts)), before, rtol=1e-9, atol=1e-9 * (1 + before.max()))
               for s, c in ((lat.V, lat.counts[1]), (lat.W, lat.counts[2])) if c > 1):
            return axis
    return None


def _boxes(ranges, qid, el) -> np.ndarray:
    """Expand per-(query, element) index boxes [lo, hi]^3 into candidate rows."""
    (li, hi_i), (lj, hj), (lk, hk) = ranges
    keep = (hi_i >= li) & (hj >= lj) & (hk >= lk)
    li, hi_i, lj, hj, lk, hk, qid, el = (x[keep] for x in (li, hi_i, lj, hj, lk, hk, qid, el))
    r1, i = expand_ranges(li, hi_i)
    r2, j = expand_ranges(lj[r1], hj[r1])
    r1 = r1[r2]
    r3, k = expand_ranges(lk[r1], hk[r1])
    r1, i, j = r1[r3], i[r2][r3], j[r3]
    return np.stack([qid[r1], i, j, k, el[r1]], axis=1)


def _uv_candidates(lat: Lattice, t: dict, pl: _Plan, qc, qr) -> np.ndarray:
    """The general algorithm over W-rows (§7.3), with culling levels: a block of W-rows
    survives if W**k of its bounding ball meets the query for some k in the block's range;
    then each W-row's group ball, then each element's own RangeFinder range."""
    mw = pl.maps[2]
    nq, nb, ne, nv = len(qc), len(t["kr"]), pl.elements, lat.counts[1]
    qext = ball_extents(mw, qc, qr)
    lo, hi = candidate_range(mw, t["kext"], _q(qext, expand=1), (nq, nb))
    rows, k = expand_ranges(lo.reshape(-1), hi.reshape(-1))
    qb, bb = rows // nb, rows % nb
    hit = _moved_ball_hits([(lat.W, k)], t["kc"][bb], t["kr"][bb], qc[qb], qr[qb])
    pairs = np.unique(qb[hit] * nb + bb[hit])
    qb, bb = pairs // nb, pairs % nb
    # W-rows (i, j) of the surviving blocks, their group ranges and moved group balls
    pr, off = expand_ranges(np.zeros(len(pairs), np.int64), t["starts"][bb + 1] - t["starts"][bb] - 1)
    row, qid = t["order"][t["starts"][bb[pr]] + off], qb[pr]
    lo, hi = candidate_range(mw, _take(t["gext"], row), _q(qext, qid), row.shape)
    r, k = expand_ranges(lo, hi)
    row, qid = row[r], qid[r]
    hit = _moved_ball_hits([(lat.W, k)], t["gc"][row], t["gr"][row], qc[qid], qr[qid])
    row, qid, k = row[hit], qid[hit], k[hit]
    el = np.tile(np.arange(ne), len(row))
    row, qid, k = np.repeat(row, ne), np.repeat(qid, ne), np.repeat(k, ne)
    lo, hi = candidate_range(mw, _take(t["ext"], row, el), _q(qext, qid), row.shape)
    keep = (k >= lo) & (k <= hi)
    row, qid, k, el = row[keep], qid[keep], k[keep], el[keep]
    return np.stack([qid, row // nv, row % nv, k, el], axis=1)


def _moved_ball_hits(moves, c, r, qc, qr) -> np.ndarray:
    """Does ball S_m**p_m ∘ … ∘ S_1**p_1 (c, r) meet query ball (qc, qr)? ``moves`` lists
    (similarity, integer powers (N,)) in the order applied; vectorized over N."""
    if len(c) == 0:
        return np.zeros(0, bool)
    c, r = c.copy(), r.astype(float).copy()
    for s, p in moves:
        lo = int(p.min())
        m = np.ascontiguousarray(s.power_matrices(np.arange(lo, int(p.max()) + 1))[:, :3])[p - lo]
        c = (m[:, :, :3] @ c[:, :, None])[:, :, 0] + m[:, :, 3]
        r = r * s.factor ** p.astype(float)
    return ball_ball_interfere(c, r * (1 + 1e-9) + 1e-12, qc, qr)


def cached_plan(lat: Lattice) -> _Plan:
    return cached(lat, "rangefinder", plan)


# ----- the compiled forms (``_rangefinder.c``) -------------------------------------------------------
# the compiled form's layout of one row map (``_rangefinder.c``: M_*), MAP_WIDTH doubles
MAP_WIDTH = 32
EXT_KEYS = ("t", "d", "r")  # the order of a template's extents, two doubles each


def packed_map(m: RowMap) -> np.ndarray:
    """A row map as the compiled forms read it: count, T-map (flag, a, origin·a, |a|), D-map
    (flag, log d, F), R-map (flag, θ, axis, point, ref, axis × ref, period)."""
    row = np.zeros(MAP_WIDTH)
    row[0] = m.count
    if m.a is not None:
        row[1], row[2:5], row[5], row[6] = 1.0, m.a, m.origin @ m.a, np.linalg.norm(m.a)
    if m.log_d is not None:
        row[7], row[8], row[9:12] = 1.0, m.log_d, m.fixed
    if m.theta is not None:
        row[12], row[13], row[14:17], row[17:20], row[20:23] = 1.0, m.theta, m.axis, m.point, m.ref
        row[23:26], row[26] = np.cross(m.axis, m.ref), m.period
    return row


def packed_extents(ext: dict, count: int) -> np.ndarray:
    """(count, 6) template extents [t_s, t_e, d_s, d_e, r_s, r_e] (zeros for a map absent)."""
    out = np.zeros((count, 2 * len(EXT_KEYS)))
    for col, key in enumerate(EXT_KEYS):
        if key in ext:
            out[:, 2 * col], out[:, 2 * col + 1] = (np.reshape(x, -1) for x in ext[key])
    return out



def compiled_fits(lat: Lattice) -> bool:
    """Is the compiled form built, and do its hit keys ((i nv + j) nw + k) · max(nodes,
    patterns) + x stay in int64 for ``lat``?"""
    nu, nv, nw = lat.counts
    return _compiled is not None and nu * nv * nw * max(len(lat.nodes), len(lat.beams), 1) < MAX_KEY


def _path_kernel(lat: Lattice, pl: _Plan) -> tuple:
    """The O(ū) or O(ūv̄) path's tables as ``_rangefinder.u_path`` / ``uv_path`` read them:
    (reach of the cached powers, arrays), cached on the plan."""
    if "kernel" not in pl.tables:
        t = _templates(lat, pl)
        nu, nv = lat.counts[:2]
        ne = pl.elements
        f64 = lambda x: np.ascontiguousarray(x, dtype=float)  # noqa: E731
        powers = [f64(x) for _, m, f in _power_rows(lat, pl) for x in (m.reshape(-1, 12), f)]
        tail = (*powers, f64(lat.template_centers), f64(lat.template_radii), _pattern_table(lat),
                np.array([TOUCH_TOL, RANGE_SLACK, MAX_WRAP_STEPS], dtype=float))
        maps = np.concatenate([packed_map(m) for m in pl.maps])
        if pl.path == "u":
            axis = np.concatenate(t["axis"]) if "axis" in t else np.zeros(0)
            band = np.stack(t["rho"], axis=1) if "axis" in t else np.zeros(0)
            arrays = (maps, packed_extents(t["gext_v"], nu), packed_extents(t["gext_w"], nu),
                      packed_extents(t["ext_v"], nu * ne), packed_extents(t["ext_w"], nu * ne), f64(t["gc"]),
                      f64(t["gr"]), f64(axis), f64(band), *tail)
        else:
            nb = len(t["kr"])
            arrays = (maps, packed_extents(t["gext"], nu * nv), packed_extents(t["ext"], nu * nv * ne),
                      f64(t["gc"]), f64(t["gr"]), f64(t["kc"]), f64(t["kr"]), packed_extents(t["kext"], nb),
                      np.ascontiguousarray(t["order"], dtype=np.int64),
                      np.ascontiguousarray(t["starts"], dtype=np.int64), *tail)
        pl.tables["kernel"] = (_power_rows(lat, pl)[0][0], arrays)
    return pl.tables["kernel"]


def _hits_compiled(lat: Lattice, pl: _Plan, qc: np.ndarray, qr: np.ndarray):
    """The O(ū) or O(ūv̄) path and its exact tests, compiled: node hits and beam hits (qid, i,
    j, k, x)."""
    reach, arrays = _path_kernel(lat, pl)
    run = _compiled.u_path if pl.path == "u" else _compiled.uv_path
    nodes, node_ends, beams, beam_ends = run((*lat.counts, len(lat.nodes)), reach, *arrays,
                                             np.ascontiguousarray(qc, dtype=float),
                                             np.ascontiguousarray(qr, dtype=float))
    return _with_qid(nodes, node_ends), _with_qid(beams, beam_ends)


def _with_qid(rows: bytes, ends: bytes) -> np.ndarray:
    """Kernel rows (m, 4) with per-query ends as (qid, i, j, k, x) rows (m, 5)."""
    rows, ends = np.frombuffer(rows, np.int64).reshape(-1, 4), np.frombuffer(ends, np.int64)
    qid = np.repeat(np.arange(len(ends)), np.diff(ends, prepend=0))
    return np.concatenate([qid[:, None], rows], axis=1)


# ----- exact tests on candidates --------------------------------------------------------------------
def _power_rows(lat: Lattice, pl: _Plan):
    """Cached rows [S**p]_{3x4} and factors s**p of U, V, W for p in [-reach, count + reach)."""
    if "pow" not in pl.tables:
        reach = max([abs(x) for b in lat.beams for x in b.offset], default=0)
        out = []
        for s, n in zip((lat.U, lat.V, lat.W), lat.counts):
            p = np.arange(-reach, n + reach)
            out.append((reach, np.ascontiguousarray(s.power_matrices(p)[:, :3]), s.factor ** p.astype(float)))
        pl.tables["pow"] = out
    return pl.tables["pow"]


def _balls_fast(lat: Lattice, pl: _Plan, idx: np.ndarray):
    """Centres and radii in the lattice frame of nodes (N, 4) [i, j, k, n], by cached powers."""
    c = lat.template_centers[idx[:, 3]]
    r = lat.template_radii[idx[:, 3]].copy()
    for col, (reach, rows, fac) in enumerate(_power_rows(lat, pl)):
        m = rows[idx[:, col] + reach]  # ((m0 x0 + m1 x1) + m2 x2) + m3 per row, as the compiled form
        c = m[:, :, 0] * c[:, None, 0] + m[:, :, 1] * c[:, None, 1] + m[:, :, 2] * c[:, None, 2] + m[:, :, 3]
        r *= fac[idx[:, col] + reach]
    return c, r


def _exact(lat: Lattice, cand: np.ndarray, qc: np.ndarray, qr: np.ndarray, pl: _Plan | None = None):
    """Split candidates into node hits and beam hits (qid, i, j, k, n|pattern), exactly tested."""
    balls = (lambda idx: frame_balls(lat, idx)) if pl is None else (lambda idx: _balls_fast(lat, pl, idx))
    nn = len(lat.nodes)
    nu, nv, nw = lat.counts
    is_node = cand[:, 4] < nn
    nodes = cand[is_node]
    hit = np.zeros(0, bool)
    if len(nodes):
        c, r = balls(nodes[:, 1:])
        hit = ball_ball_interfere(c, r, qc[nodes[:, 0]], qr[nodes[:, 0]])
    node_hits = nodes[hit]
    beams = cand[~is_node].copy()
    beams[:, 4] -= nn
    pats = _pattern_table(lat)
    if len(beams):
        pp = pats[beams[:, 4]]
        ti, tj, tk = beams[:, 1] + pp[:, 2], beams[:, 2] + pp[:, 3], beams[:, 3] + pp[:, 4]
        valid = (ti >= 0) & (ti < nu) & (tj >= 0) & (tj < nv) & (tk >= 0) & (tk < nw)
        beams, pp, ti, tj, tk = beams[valid], pp[valid], ti[valid], tj[valid], tk[valid]
    if len(beams):
        ca, ra = balls(np.stack([beams[:, 1], beams[:, 2], beams[:, 3], pp[:, 0]], axis=1))
        cb, rb = balls(np.stack([ti, tj, tk, pp[:, 1]], axis=1))
        hit = ball_beam_interfere(qc[beams[:, 0]], qr[beams[:, 0]], ca, ra, cb, rb)
        beams = beams[hit]
    return node_hits, beams


def to_frame(lat: Lattice, c: np.ndarray, r: np.ndarray):
    g = lat.placement
    if g.kind == "identity":
        return c, r
    return g.inverse().apply_points(c), r / g.factor


PATH_ORDER = ("1", "u", "uv")  # §7.3.1: each path's conditions include the next one's


def lattice_hits(lat: Lattice, c: np.ndarray, r: np.ndarray, path: str | None = None):
    """RangeFinder BIQ: (node hits (N, 5), beam hits (M, 5), path) as (qid, i, j, k, x).
    ``path`` forces a slower path than the detected one ("u" or "uv"; benchmarks, Table 7.2)."""
    graded = lat.radius_field is not None
    search = lat.bounding_lattice() if graded else lat  # graded radii: candidates of the bounding balls
    pl = cached_plan(search)
    if path is not None and path != pl.path:
        if path not in PATH_ORDER or PATH_ORDER.index(path) < PATH_ORDER.index(pl.path):
            raise PleError(f"path {echo(path)} is not available on this lattice (detected {echo(pl.path)}; "
                           f"only slower paths {PATH_ORDER[PATH_ORDER.index(pl.path):]} can be forced)")
        pl = pl.forced.setdefault(path, _Plan(path, pl.maps, pl.elements))
    qc, qr = to_frame(lat, c, r)
    fast = not graded and max(lat.counts) <= MAX_POWER_TABLE  # cached powers know no field
    if pl.path in ("u", "uv") and fast and compiled_fits(lat):
        return *_hits_compiled(lat, pl, qc, qr), pl.path
    node_parts, beam_parts = [], []
    for s in range(0, len(qc), QUERY_BATCH):
        cand = _candidates(search, pl, qc[s:s + QUERY_BATCH], qr[s:s + QUERY_BATCH])
        cand[:, 0] += s
        nh, bh = _exact(lat, cand, qc, qr, pl if fast else None)
        node_parts.append(nh)
        beam_parts.append(bh)
    cat = lambda parts: np.concatenate(parts) if parts else np.zeros((0, 5), np.int64)  # noqa: E731
    return cat(node_parts), cat(beam_parts), pl.path


def lattice_any(lat: Lattice, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """bool (q,): does each query ball interfere with some node or beam (RangeFinder path)?"""
    nh, bh, _ = lattice_hits(lat, c, r)
    out = np.zeros(len(c), dtype=bool)
    out[nh[:, 0]] = True
    out[bh[:, 0]] = True
    return out
