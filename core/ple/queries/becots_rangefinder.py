"""BeCOTS RangeFinder (thesis §8): constant-time ball-interference queries on BeCOTS slabs.

In log-polar coordinates about the field's apex F and axis T (``rho = ln |FP|``, ``theta`` the
angle about T) every node-group step is a translation, so the linear map
``K = diag(nu, nv) · J⁻¹`` (J of Eq. 4.10) turns the BeCOTS pattern into the regular pattern
``shape[i, j] = shape[0, 0] + (i, j)`` of index space (the pre-image of §8.1). A ball's
*log-polar bound* — two planes through the axis tangent to it and two spheres about F
tangent to it, i.e. the box ``[rho0, rho1] × [theta0, theta1]``; this is the umbrella
projection of §8.2 read directly in log-polar coordinates — maps to a parallelogram whose
axis-aligned box gives candidate index ranges ``I × J`` by the translation RangeFinder
(§7.1.3): ``I = [ceil(c - b), floor(d - a)]``. Branch handling: the query's angle interval is
lifted by every ``2π k`` that meets the lattice's angle range, one candidate box per branch.
Candidates are then tested exactly (ball–ball, ball–cone-beam). Cost per query: the number
of template shapes × candidates per shape, independent of nu and nv.

Special cases: a query ball touching the axis gets the full circle of angles (every branch);
a ball containing F gets an unbounded rho range (clipped to the lattice). The cylinder kind
uses the height along T instead of ``ln |FP|``; the translation kind (a regular slab) uses
affine coordinates directly. W (count > 1) and the placement are handled by moving the
field with ``G ∘ W**k`` for each k (O(nw) per query).

Everything that does not depend on the queries (shape boxes, limits, shells, the template in
the field's local frame, per-index cos/sin/scale tables) is a ``_Plan`` cached on the lattice
and rebuilt when the lattice changes; a batch of queries is then one vectorized pass over
flat arrays (bounds, candidate windows, exact tests in the template frame, one sort), with no
Python loop per query, branch or candidate.
"""

from __future__ import annotations

import numpy as np

from ..algebra.elements import TOUCH_TOL
from ..algebra.similarity import Similarity
from ..errors import PleError
from ..model.becots import TWO_PI, BeCOTSField, becots_of
from ..model.becots_builders import stack_layer_coordinate
from ..model.lattice import Lattice
from .hits import BIQResult, check_queries, split_hits
from .plans import cached
from .rangefinder import lattice_hits

INDEX_SLACK = 1e-7  # index-space slack on candidate ranges (conservative rounding)
KEY_LIMIT = 2 ** 62  # hit keys (query, kind, i, j, k, id) packed into one int64 below this bound
TABLE_LIMIT = 1 << 22  # largest gu + gv for per-index cos/sin/scale tables (else trig per candidate)
TINY_LOG = -700.0  # ln of a distance that is zero for all purposes (a ball containing F)


def query(lat: Lattice, centers, radii) -> list:
    """Per query ball (centres (q, 3), radii (q,)), the BIQResult of ``ple.biq`` (path "becots")."""
    c, r = check_queries(centers, radii)
    try:
        plan = _plan(lat)
    except PleError:  # U or V changed after set_becots (e.g. with_counts): the general path
        plan = None
    if plan is None:
        lat.validate()
        nh, bh, path = lattice_hits(lat, c, r)
        return split_hits(len(c), nh, bh, path)
    return plan.query(c, r)


def is_becots(lat: Lattice) -> bool:
    """Is ``lat`` still the BeCOTS slab that ``lat.becots`` describes?"""
    try:
        becots_of(lat)
    except PleError:
        return False
    return True


def query_subset(lat: Lattice, c: np.ndarray, r: np.ndarray, nodes=None, beams=None, select=None) -> list:
    """BIQ restricted to template nodes ``nodes`` and beam-patterns ``beams`` (None: all);
    ``select`` (q, m) optionally picks, per query, m of those shapes (positions in the list
    nodes + beams) so that each query costs O(m) whatever the template size."""
    plan = _plan(lat)
    if plan is None:
        becots_of(lat)  # raises the PleError that says why the lattice is not a BeCOTS slab
        raise PleError("beam-patterns with dk != 0 on a BeCOTS slab with W count > 1: use the general BIQ path")
    ids = None
    if nodes is not None or beams is not None or select is not None:
        nid = np.arange(plan.nn) if nodes is None else np.asarray(nodes, dtype=np.int64).reshape(-1)
        bid = np.arange(plan.nb) if beams is None else np.asarray(beams, dtype=np.int64).reshape(-1)
        ids = np.concatenate([nid, plan.nn + bid])[None]
        if select is not None:
            ids = ids[0][np.asarray(select, dtype=np.int64).reshape(len(c), -1)]
    return plan.query(np.asarray(c, float), np.asarray(r, float), ids)


# ----- the per-lattice plan ---------------------------------------------------------------------------
def _plan(lat: Lattice):
    """The cached per-lattice constants (a ``_Plan``), rebuilt when the lattice changed; None if
    the lattice cannot use this RangeFinder (special case: beam-patterns with dk != 0 and W
    count > 1 are not regular in index space). Raises PleError if ``lat.becots`` is stale."""
    becots_of(lat)  # checked on every call: a later set_u/set_v makes the description stale
    return cached(lat, "becots", _build_plan)


def _build_plan(lat: Lattice):
    lat.validate()
    return None if lat.w.count > 1 and any(b.dk for b in lat.beams) else _Plan(lat, becots_of(lat))


class _Plan:
    """Per-lattice constants: one ``_Layer`` per W copy (field moved by ``G ∘ W**k``)."""

    def __init__(self, lat: Lattice, info):
        self.nn, self.nb = len(lat.nodes), len(lat.beams)
        self.gu, self.gv = info.group_counts
        self.nw = lat.w.count
        self.layers = []
        for k in range(self.nw):
            g = lat.placement if k == 0 else Similarity.from_matrix(lat.placement.matrix @ (lat.W ** k).matrix)
            tc = g.apply_points(lat.template_centers)
            tr = lat.template_radii * g.factor
            self.layers.append(_Layer(info.field.placed(g), info.counts, info.group_counts, tc, tr, lat.beams))

    def query(self, c: np.ndarray, r: np.ndarray, ids=None) -> list:
        parts = [layer.hits(c, r, ids, k) for k, layer in enumerate(self.layers)]
        cols = zip(*(part[:6] for part in parts))
        qid, isbeam, ci, cj, kk, x = (np.concatenate(col) for col in cols) if len(parts) > 1 else parts[0][:6]
        # a hit can repeat only across branches, W copies or a padded selection
        unique = len(parts) == 1 and parts[0][6] and ids is None
        return self._split(len(c), qid, isbeam, ci, cj, kk, x, unique)

    def _split(self, q: int, qid, isbeam, ci, cj, kk, x, unique: bool = False) -> list:
        """Per-query sorted, de-duplicated BIQResults: one integer key per hit (query, node or
        beam, i, j, k, id), one sort, then views of one (n, 4) array."""
        nx = max(self.nn, self.nb, 1)
        if 2 * q * self.gu * self.gv * self.nw * nx < KEY_LIMIT:
            key = ((((qid * 2 + isbeam) * self.gu + ci) * self.gv + cj) * self.nw + kk) * nx + x
            order = np.argsort(key, kind="stable")
            if not unique and len(key) > 1:
                ks = key[order]
                order = order[np.concatenate([[True], ks[1:] != ks[:-1]])]
            rows = np.empty((len(order), 4), np.int64)
            for col, arr in enumerate((ci, cj, kk, x)):
                rows[:, col] = arr.take(order)
            grp = (qid * 2 + isbeam).take(order)
        else:  # special case: keys would overflow int64, sort the columns instead
            rows = np.stack([qid * 2 + isbeam, ci, cj, kk, x], axis=1)
            rows = rows[np.lexsort(rows.T[::-1])]
            if len(rows) > 1:
                rows = rows[np.concatenate([[True], np.any(rows[1:] != rows[:-1], axis=1)])]
            grp, rows = rows[:, 0], rows[:, 1:]
        b = np.concatenate([[0], np.cumsum(np.bincount(grp, minlength=2 * q))]).tolist()
        empty = rows[:0]  # shared by the queries without hits (no view to build)
        return [BIQResult(rows[b0:b1] if b1 > b0 else empty, rows[b1:b2] if b2 > b1 else empty, "becots")
                for b0, b1, b2 in zip(b[0:-1:2], b[1::2], b[2::2])]


# ----- bounds ---------------------------------------------------------------------------------------
class _Coords:
    """Index-space coordinates of one field: boxes of balls and beams, and the lift of angles."""

    def __init__(self, fld: BeCOTSField, counts):
        self.fld = fld
        nu, nv = counts
        self.counts = counts
        if fld.kind == "translation":
            basis = np.stack([fld.tu / nu, fld.tv / nv], axis=1)  # (3, 2): one index step each
            self.dual = np.linalg.pinv(basis)  # (2, 3): index coordinates of P - A
            self.dual_norm = np.linalg.norm(self.dual, axis=1)
            self.normal = np.cross(fld.tu, fld.tv) / np.linalg.norm(np.cross(fld.tu, fld.tv))
        else:
            (a, b), (c, d) = fld.jacobian
            inv = np.array([[d, -b], [-c, a]]) / (a * d - b * c)  # 2x2 inverse of J, Eq. 4.12
            self.k = np.array([[nu], [nv]]) * inv  # (rho, theta) -> index space
            self.e1, self.e2 = fld.frame
            self.ref = np.linalg.norm(fld.a - fld.apex)

    def ball_polar(self, c: np.ndarray, r: np.ndarray):
        """Log-polar bound of balls: (rho0, rho1, theta_c, half) with theta in (-π, π]."""
        fld = self.fld
        rel = c - fld.apex
        h = rel @ fld.axis
        radial = np.sqrt(np.maximum(np.einsum("ij,ij->i", rel, rel) - h * h, 0.0))
        theta = np.arctan2(rel @ self.e2, rel @ self.e1)
        with np.errstate(invalid="ignore", divide="ignore"):
            half = np.where(r < radial, np.arcsin(np.minimum(r / np.where(radial > 0, radial, 1.0), 1.0)), np.pi)
        if fld.kind == "cone":
            d = np.linalg.norm(rel, axis=1)
            with np.errstate(divide="ignore"):
                rho0 = np.where(d > r, np.log(np.maximum(d - r, 1e-300) / self.ref), TINY_LOG)
            rho1 = np.log((d + r) / self.ref)
        else:  # special case cylinder: rho is the height along T
            h0 = (fld.a - fld.apex) @ fld.axis
            rho0, rho1 = h - h0 - r, h - h0 + r
        return rho0, rho1, theta, half

    def beam_polar(self, a, ra, b, rb):
        """Log-polar bound of cone-beams hull(ball a, ball b), conservative: rho from the
        segment's distance to F minus the larger radius, theta from both ends unless the beam
        may touch the axis (then the full circle)."""
        fld = self.fld
        a0, a1, ta, ha = self.ball_polar(a, ra)
        b0, b1, tb, hb = self.ball_polar(b, rb)
        tb = ta + (tb - ta + np.pi) % TWO_PI - np.pi  # lift b's angle next to a's
        lo = np.minimum(ta - ha, tb - hb)
        hi = np.maximum(ta + ha, tb + hb)
        rmax = np.maximum(ra, rb)
        # projected segment vs the axis point: the hull avoids the axis if farther than rmax
        pa = (a - fld.apex) - np.outer((a - fld.apex) @ fld.axis, fld.axis)
        pb = (b - fld.apex) - np.outer((b - fld.apex) @ fld.axis, fld.axis)
        seg = _point_segment_distance(np.zeros_like(pa), pa, pb)
        full = (seg <= rmax) | (hi - lo >= TWO_PI)
        mid = np.where(full, ta, (lo + hi) / 2)
        half = np.where(full, np.pi, (hi - lo) / 2)
        if fld.kind == "cone":
            dmin = _point_segment_distance(np.broadcast_to(fld.apex, a.shape), a, b) - rmax
            with np.errstate(divide="ignore"):
                rho0 = np.where(dmin > 0, np.log(np.maximum(dmin, 1e-300) / self.ref), TINY_LOG)
            rho0 = np.minimum(rho0, np.minimum(a0, b0))
        else:
            rho0 = np.minimum(a0, b0)
        return rho0, np.maximum(a1, b1), mid, half

    def ball_shell(self, c: np.ndarray, r: np.ndarray):
        """Interval of the *shell coordinate* that every node-group step preserves — the angle
        from the axis (cone), the distance to the axis (cylinder), the offset from the plane
        (translation) — over balls: the conical shell test of §8.2."""
        fld = self.fld
        if fld.kind == "translation":
            n = (c - fld.a) @ self.normal
            return n - r, n + r
        rel = c - fld.apex
        h = rel @ fld.axis
        d = np.linalg.norm(rel, axis=1)
        if fld.kind == "cylinder":
            radial = np.sqrt(np.maximum(d * d - h * h, 0.0))
            return radial - r, radial + r
        phi = np.arccos(np.clip(h / np.where(d > 0, d, 1.0), -1.0, 1.0))
        spread = np.where(d > r, np.arcsin(np.minimum(r / np.where(d > 0, d, 1.0), 1.0)), np.inf)
        return phi - spread, phi + spread

    def beam_shell(self, a, ra, b, rb):
        """Shell-coordinate interval of cone-beams: the segment's extreme values (the angle
        from the axis along a segment peaks at one interior t, found in closed form) widened
        by the larger radius."""
        fld = self.fld
        rmax = np.maximum(ra, rb)
        if fld.kind == "translation":
            na, nb = (a - fld.a) @ self.normal, (b - fld.a) @ self.normal
            return np.minimum(na, nb) - rmax, np.maximum(na, nb) + rmax
        pa, pb = a - fld.apex, b - fld.apex
        if fld.kind == "cylinder":
            ra_, rb_ = (np.linalg.norm(p - np.outer(p @ fld.axis, fld.axis), axis=1) for p in (pa, pb))
            proj_a, proj_b = (p - np.outer(p @ fld.axis, fld.axis) for p in (pa, pb))
            near = _point_segment_distance(np.zeros_like(proj_a), proj_a, proj_b)
            return near - rmax, np.maximum(ra_, rb_) + rmax
        # cos φ(t) = (α + β t) / sqrt(γ + 2 δ t + ε t²) has one critical t* = (αδ - βγ) / (βδ - αε)
        ab = pb - pa
        al, be = pa @ fld.axis, ab @ fld.axis
        ga, de, ep = np.einsum("ij,ij->i", pa, pa), np.einsum("ij,ij->i", pa, ab), np.einsum("ij,ij->i", ab, ab)
        den = be * de - al * ep
        tstar = np.clip((al * de - be * ga) / np.where(den != 0, den, 1.0), 0.0, 1.0)
        ts = np.stack([np.zeros_like(al), np.ones_like(al), np.where(den != 0, tstar, 0.0)])  # (3, n)
        p = pa[None] + ts[..., None] * ab[None]
        norm = np.linalg.norm(p, axis=2)
        phi = np.arccos(np.clip((p @ fld.axis) / np.where(norm > 0, norm, 1.0), -1.0, 1.0))
        dmin = _point_segment_distance(np.zeros_like(pa), pa, pb)
        spread = np.where(dmin > rmax, np.arcsin(np.minimum(rmax / np.where(dmin > 0, dmin, 1.0), 1.0)), np.inf)
        return phi.min(0) - spread, phi.max(0) + spread

    def index_box(self, rho0, rho1, lo, hi):
        """Axis-aligned index-space box (n, 4: i0, i1, j0, j1) of log-polar boxes."""
        corners = np.stack([np.stack([rho0, lo]), np.stack([rho0, hi]), np.stack([rho1, lo]),
                            np.stack([rho1, hi])])  # (4, 2, n)
        idx = np.einsum("ab,cbn->can", self.k, corners)  # (4, 2, n)
        return np.stack([idx[:, 0].min(0), idx[:, 0].max(0), idx[:, 1].min(0), idx[:, 1].max(0)], axis=1)

    def affine_box(self, c, r):
        """Special case translation field: exact index-space box of balls (n, 4)."""
        x = (c - self.fld.a) @ self.dual.T  # (n, 2)
        ext = r[:, None] * self.dual_norm[None]
        return np.stack([x[:, 0] - ext[:, 0], x[:, 0] + ext[:, 0], x[:, 1] - ext[:, 1], x[:, 1] + ext[:, 1]], axis=1)


def _point_segment_distance(p, a, b) -> np.ndarray:
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(den > 0, den, 1.0), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ab - p, axis=1)




# ----- the query ------------------------------------------------------------------------------------
class _Layer:
    """Constants of one placed field, computed once per lattice: the template shapes' index-space
    boxes (§8.1–8.2), limits and shell intervals, the lattice's angle range, and the template
    shapes in the field's local frame (origin F, rows e1, e2, T) for the exact tests."""

    def __init__(self, fld: BeCOTSField, counts, group_counts, tc, tr, beams):
        nu, nv = counts
        gu, gv = group_counts
        self.kind = fld.kind
        co = _Coords(fld, counts)
        nn = len(tc)
        # template shapes: nodes first, then beams (from-group (0, 0) to (di, dj)); a beam-pattern
        # with dk != 0 has no instance when W count is 1 (special case: empty limits)
        lim = [(0, gu - 1, 0, gv - 1)] * nn
        ends = []
        for b in beams:
            lim.append((max(0, -b.di), min(gu, gu - b.di) - 1, max(0, -b.dj), min(gv, gv - b.dj) - 1)
                       if b.dk == 0 else (0, -1, 0, -1))
            end = fld.apply([b.di / nu], [b.dj / nv], tc[b.n2])[0]
            ends.append((tc[b.n1], tr[b.n1], end, tr[b.n2] * float(_factor(fld, b.di / nu, b.dj / nv))))
        self.lim = np.array(lim, dtype=float).reshape(-1, 4)
        ca = np.concatenate([tc, np.array([e[0] for e in ends]).reshape(-1, 3)])
        ra = np.concatenate([tr, np.array([e[1] for e in ends], dtype=float)])
        cb = np.concatenate([tc, np.array([e[2] for e in ends]).reshape(-1, 3)])
        rb = np.concatenate([tr, np.array([e[3] for e in ends], dtype=float)])
        self.is_node = np.arange(len(ra)) < nn
        self.pattern = np.concatenate([np.arange(nn), np.arange(len(beams))]).astype(np.int64)
        nb = len(beams)
        shells = [co.ball_shell(tc, tr)] + ([co.beam_shell(ca[nn:], ra[nn:], cb[nn:], rb[nn:])] if nb else [])
        self.s_lo, self.s_hi = (np.concatenate(x) for x in zip(*shells))
        if fld.kind == "translation":
            boxes = [co.affine_box(tc, tr)]
            if nb:
                sa, sb = co.affine_box(ca[nn:], ra[nn:]), co.affine_box(cb[nn:], rb[nn:])
                boxes.append(np.stack([np.minimum(sa[:, 0], sb[:, 0]), np.maximum(sa[:, 1], sb[:, 1]),
                                       np.minimum(sa[:, 2], sb[:, 2]), np.maximum(sa[:, 3], sb[:, 3])], axis=1))
            self.box = np.concatenate(boxes)
            self.origin, self.frame = fld.a.copy(), np.eye(3)
            self.dual, self.dual_norm, self.normal = co.dual, co.dual_norm, co.normal
            self.step_u, self.step_v = fld.tu / nu, fld.tv / nv
        else:
            parts = [co.ball_polar(tc, tr)] + ([co.beam_polar(ca[nn:], ra[nn:], cb[nn:], rb[nn:])] if nb else [])
            rho0, rho1, mid, half = (np.concatenate(x) for x in zip(*parts))
            self.box = co.index_box(rho0, rho1, mid - half, mid + half)
            # the lattice's angle range: template shapes shifted by every group's angle step
            (ru, wu), (rv, wv) = fld.u, fld.v
            steps_u, steps_v = (gu - 1) * wu / nu, (gv - 1) * wv / nv
            self.th_lo = float((mid - half).min()) + min(0.0, steps_u) + min(0.0, steps_v)
            self.th_hi = float((mid + half).max()) + max(0.0, steps_u) + max(0.0, steps_v)
            self.k = co.k
            self.origin, self.frame = fld.apex.copy(), np.stack([co.e1, co.e2, fld.axis])
            self.ref = co.ref
            self.h0 = float((fld.a - fld.apex) @ fld.axis)
            self.step_u, self.step_v = (ru / nu, wu / nu), (rv / nv, wv / nv)
        # the translation RangeFinder's subtrahends, in the query box's column order (i_lo, j_lo,
        # i_hi, j_hi): lower = ceil(c - b - slack), upper = floor(d - a + slack); limits likewise
        b4 = self.box
        self.sbox = np.stack([b4[:, 1] + INDEX_SLACK, b4[:, 3] + INDEX_SLACK, b4[:, 0] - INDEX_SLACK,
                              b4[:, 2] - INDEX_SLACK], axis=1)
        self.slim = self.lim[:, [0, 2, 1, 3]]
        # per-index tables (cos, sin, scale) of S(i/nu, 0)⁻¹ and S(0, j/nv)⁻¹: (3, gu), (3, gv)
        self.tables = None
        if fld.kind != "translation" and gu + gv <= TABLE_LIMIT:
            (ru, wu), (rv, wv) = self.step_u, self.step_v
            iu, jv = np.arange(gu, dtype=float), np.arange(gv, dtype=float)
            if fld.kind == "cone":  # (e cos, e sin, e) with e = exp(-rho): S⁻¹ scales by e
                tab = lambda n, w, rr: np.exp(-n * rr) * np.stack([np.cos(n * w), np.sin(n * w), np.ones_like(n)])  # noqa: E731
            else:  # cylinder: (cos, sin, slide)
                tab = lambda n, w, rr: np.stack([np.cos(n * w), np.sin(n * w), n * rr])  # noqa: E731
            self.tables = (tab(iu, wu, ru), tab(jv, wv, rv))
        # exact tests happen in the template's frame: the shapes of group (0, 0), local coordinates
        a_loc = (ca - self.origin) @ self.frame.T
        ab = (cb - self.origin) @ self.frame.T - a_loc
        self.ra, self.rb = ra, rb
        self.length = np.sqrt(np.einsum("ij,ij->i", ab, ab))
        safe = np.where(self.length > 0, self.length, 1.0)
        self.a = np.ascontiguousarray(a_loc.T)  # (3, S) columns
        self.e = np.ascontiguousarray((ab / safe[:, None]).T)
        self.sn = np.clip((ra - rb) / safe, -1.0, 1.0)  # tangent slope of the cone-beam (seed 002 §2.1)
        self.cs = np.sqrt(1.0 - self.sn * self.sn)
        # dist = da where u <= lo, db where u >= hi, else the tangent line; special cases: one
        # ball contains the other (the hull is that ball: always da, or always db)
        a_big = self.length + rb <= ra
        b_big = (self.length + ra <= rb) & ~a_big
        lo_thr = np.where(a_big, np.inf, np.where(b_big, -np.inf, 0.0))
        hi_thr = np.where(b_big, -np.inf, self.cs * self.length)
        self.table = np.concatenate([self.a, self.e, np.stack([ra, rb, self.sn, self.cs, self.length,
                                                              np.maximum(ra, rb), lo_thr, hi_thr])])  # (14, S)

    def query_bounds(self, c: np.ndarray, r: np.ndarray):
        """Local coordinates of the queries and their index-space boxes, one row per branch:
        (loc (q, 3), rows (n,) query ids, box (n, 4), shell (q,), (q,))."""
        loc = (c - self.origin) @ self.frame.T
        if self.kind == "translation":
            x = loc @ self.dual.T  # (q, 2) exact affine index coordinates
            ext = r[:, None] * self.dual_norm[None]
            n = loc @ self.normal
            box = np.concatenate([x - ext, x + ext], axis=1)  # i_lo, j_lo, i_hi, j_hi
            return loc, None, box, n - r, n + r
        x, y, h = loc[:, 0], loc[:, 1], loc[:, 2]
        rad2 = x * x + y * y
        radial = np.sqrt(rad2)
        theta = np.arctan2(y, x)
        with np.errstate(invalid="ignore", divide="ignore"):
            half = np.arcsin(np.minimum(r / radial, 1.0))
            half[~(r < radial)] = np.pi  # special case: the ball touches the axis, every angle
            if self.kind == "cone":
                d = np.sqrt(rad2 + h * h)
                rho0 = np.log(np.maximum(d - r, 1e-300) / self.ref)
                rho1 = np.maximum(np.log((d + r) / self.ref), TINY_LOG)
                rho0[~(d > r)] = TINY_LOG  # special case: the ball contains F, unbounded rho
                phi = np.arccos(np.clip(h / d, -1.0, 1.0))
                spread = np.arcsin(np.minimum(r / d, 1.0))
                phi[~(d > 0)] = 0.0
                spread[~(d > r)] = np.inf
                s_lo, s_hi = phi - spread, phi + spread
            else:  # special case cylinder: rho is the height along T, the shell the distance to T
                rho0, rho1 = h - self.h0 - r, h - self.h0 + r
                s_lo, s_hi = radial - r, radial + r
        # branches: lift the query's angle interval by every 2π k meeting the lattice's angle range
        kmin = np.ceil((self.th_lo - (theta + half)) / TWO_PI)
        kmax = np.floor((self.th_hi - (theta - half)) / TWO_PI)
        nk = np.maximum(kmax - kmin + 1, 0).astype(np.int64)
        if np.all(nk == 1):  # the common case: one branch per query
            rows = None
            lift = theta + TWO_PI * kmin
        else:
            rows = np.repeat(np.arange(len(c)), nk)
            kk = kmin[rows] + (np.arange(len(rows)) - np.repeat(np.cumsum(nk) - nk, nk))
            lift = theta[rows] + TWO_PI * kk
            rho0, rho1, half = rho0[rows], rho1[rows], half[rows]
        lo, hi = lift - half, lift + half
        # index-space box of the log-polar box: K is linear, so each bound takes one corner
        (k00, k01), (k10, k11) = self.k
        box = np.stack([k00 * (rho0 if k00 >= 0 else rho1) + k01 * (lo if k01 >= 0 else hi),
                        k10 * (rho0 if k10 >= 0 else rho1) + k11 * (lo if k11 >= 0 else hi),
                        k00 * (rho1 if k00 >= 0 else rho0) + k01 * (hi if k01 >= 0 else lo),
                        k10 * (rho1 if k10 >= 0 else rho0) + k11 * (hi if k11 >= 0 else lo)], axis=1)
        return loc, rows, box, s_lo, s_hi

    def candidates(self, rows, box, s_lo, s_hi, ids):
        """Flat candidate arrays (row, shape, i, j) of every (query row, shape) pair: the
        translation RangeFinder I = [ceil(c - b), floor(d - a)] ∩ limits, and likewise J (§7.1.3),
        after the conical shell test (§8.2)."""
        if rows is not None:
            s_lo, s_hi = s_lo[rows], s_hi[rows]
        if ids is None:  # every template shape
            sid = None
            sb, sl, lo_, hi_ = self.sbox[None], self.slim[None], self.s_lo[None], self.s_hi[None]
        else:  # (1, m) the same shapes for every query, or (q, m) a selection per query
            sid = ids[rows] if rows is not None and len(ids) > 1 else ids
            sb, sl, lo_, hi_ = self.sbox[sid], self.slim[sid], self.s_lo[sid], self.s_hi[sid]
        i0 = np.maximum(sl[..., 0], np.ceil(box[:, None, 0] - sb[..., 0]))
        j0 = np.maximum(sl[..., 1], np.ceil(box[:, None, 1] - sb[..., 1]))
        ni = np.minimum(sl[..., 2], np.floor(box[:, None, 2] - sb[..., 2])) - i0 + 1
        nj = np.minimum(sl[..., 3], np.floor(box[:, None, 3] - sb[..., 3])) - j0 + 1
        ok = (ni > 0) & (nj > 0) & (s_hi[:, None] >= lo_) & (hi_ >= s_lo[:, None])
        nz = np.flatnonzero(ok)
        width = ok.shape[1]
        if len(nz) == 0:
            e = np.zeros(0, np.int64)
            return e, e, e, e
        nj = nj.reshape(-1)[nz].astype(np.int64)
        cnt = ni.reshape(-1)[nz].astype(np.int64) * nj
        pair = np.repeat(np.arange(len(nz)), cnt)
        off = np.arange(len(pair)) - (np.cumsum(cnt) - cnt)[pair]
        di, dj = np.divmod(off, nj[pair])
        ci = i0.reshape(-1)[nz].astype(np.int64)[pair] + di
        cj = j0.reshape(-1)[nz].astype(np.int64)[pair] + dj
        row, col = np.divmod(nz, width)
        shape = (col if sid is None else np.broadcast_to(sid, ok.shape).reshape(-1)[nz])[pair]
        return row[pair], shape, ci, cj

    def hits(self, c: np.ndarray, r: np.ndarray, ids, k: int):
        """Hit arrays (qid, is_beam, i, j, k, node id or pattern) of this placed field."""
        loc, rows, box, s_lo, s_hi = self.query_bounds(c, r)
        row, shape, ci, cj = self.candidates(rows, box, s_lo, s_hi, ids)
        qid = row if rows is None else rows[row]
        if len(qid) == 0:
            e = np.zeros(0, np.int64)
            return e, e, e, e, e, e, True
        # move each query into the template's frame by S(i/nu, j/nv)⁻¹ (so shapes are constants)
        x, y, z, rq = self._to_template(loc, r, qid, ci, cj)
        # exact tests in one pass over columns: ball–ball for nodes, ball–cone-beam for beams
        # (the formulas of ple.elements.beam_distance, thresholds precomputed per shape)
        ax, ay, az, ex, ey, ez, ra, rb, sn, cs, length, big, lo_thr, hi_thr = self.table.take(shape, axis=1)
        dx, dy, dz = x - ax, y - ay, z - az
        ap2 = dx * dx + dy * dy + dz * dz
        rr = rq + ra
        node_hit = ap2 <= rr * rr * (1 + TOUCH_TOL) + TOUCH_TOL * TOUCH_TOL
        t = dx * ex + dy * ey + dz * ez  # along the axis a→b
        t2 = t * t
        y2 = np.maximum(ap2 - t2, 0.0)
        yy = np.sqrt(y2)
        u = cs * t - sn * yy  # position along the tangent direction (seed 002 §2.1)
        da = np.sqrt(t2 + y2) - ra
        tb = t - length
        db = np.sqrt(tb * tb + y2) - rb
        dist = np.where(u <= lo_thr, da, np.where(u >= hi_thr, db, sn * t + cs * yy - ra))
        beam_hit = dist <= rq + TOUCH_TOL * np.maximum(big, rq)
        is_node = self.is_node[shape]
        s = np.flatnonzero(np.where(is_node, node_hit, beam_hit))
        return (qid[s], (~is_node[s]).astype(np.int64), ci[s], cj[s], np.full(len(s), k, np.int64),
                self.pattern[shape[s]], rows is None)

    def _to_template(self, loc, r, qid, ci, cj):
        """Columns x, y, z and radius of each candidate's query ball moved by S(i/nu, j/nv)⁻¹."""
        x, y, z, rq = np.concatenate([loc, r[:, None]], axis=1).T.take(qid, axis=1)
        if self.tables is not None:  # angle addition over per-index tables: no trig per candidate
            cu, su, eu = self.tables[0].take(ci, axis=1)
            cv, sv, ev = self.tables[1].take(cj, axis=1)
            if self.kind == "cylinder":
                cth, sth = cu * cv - su * sv, su * cv + cu * sv
                return x * cth + y * sth, y * cth - x * sth, z - (eu + ev), rq
            # cone: the tables hold scale · (cos, sin), so these are s cos θ and s sin θ
            cth, sth, s = cu * cv - su * sv, su * cv + cu * sv, eu * ev
            return x * cth + y * sth, y * cth - x * sth, z * s, rq * s
        ci, cj = ci.astype(float), cj.astype(float)
        if self.kind == "translation":
            (ux, uy, uz), (vx, vy, vz) = self.step_u, self.step_v
            return x - ci * ux - cj * vx, y - ci * uy - cj * vy, z - ci * uz - cj * vz, rq
        (ru, wu), (rv, wv) = self.step_u, self.step_v
        th = ci * wu + cj * wv
        cth, sth = np.cos(th), np.sin(th)
        xr, yr = x * cth + y * sth, y * cth - x * sth
        if self.kind == "cylinder":  # slide back along T
            return xr, yr, z - (ci * ru + cj * rv), rq
        s = np.exp(-(ci * ru + cj * rv))
        return xr * s, yr * s, z * s, rq * s


def _factor(fld: BeCOTSField, x, y):
    if fld.kind != "cone":
        return np.ones_like(np.asarray(x, float))
    return np.exp(np.asarray(x, float) * fld.u[0] + np.asarray(y, float) * fld.v[0])


def stack_pmc(lat: Lattice, pts) -> np.ndarray:
    """Point membership on a BeCOTS stack in O(1) per point (§6.3): test only the two
    nearest layers and the beams between them (through the BeCOTS RangeFinder)."""
    info = becots_of(lat)
    q = np.asarray(pts, float).reshape(-1, 3)
    t = stack_layer_coordinate(lat, q)
    st = info.stack
    lower = np.clip(np.floor(np.nan_to_num(t)), 0, max(st.layers - 2, 0)).astype(np.int64)
    per, nn = st.nodes_per_layer, len(lat.nodes)
    # per pair (lo, lo + 1) of nearest layers: its nodes and the beam-patterns among them, as
    # positions in the shape list (nodes, then beams); short lists are padded by repetition
    lists = []
    for lo in range(max(st.layers - 1, 1)):
        near = {lo, min(lo + 1, st.layers - 1)}
        lists.append([k * per + x for k in sorted(near) for x in range(per)]
                     + [nn + p for p, b in enumerate(lat.beams) if b.n1 // per in near and b.n2 // per in near])
    width = max(len(x) for x in lists)
    table = np.array([x + [x[0]] * (width - len(x)) for x in lists], dtype=np.int64)
    res = query_subset(lat, q, np.zeros(len(q)), select=table[lower])
    return np.array([len(x.nodes) > 0 or len(x.beams) > 0 for x in res], dtype=bool)
