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
"""

from __future__ import annotations

import numpy as np

from .becots import TWO_PI, BeCOTSField, becots_of
from .elements import ball_ball_interfere, ball_beam_interfere
from .errors import PleError
from .lattice import Lattice
from .similarity import Similarity

INDEX_SLACK = 1e-7  # index-space slack on candidate ranges (conservative rounding)
TINY_LOG = -700.0  # ln of a distance that is zero for all purposes (a ball containing F)


def query(lat: Lattice, centers, radii) -> list:
    """Per query ball (centres (q, 3), radii (q,)), the BIQResult of ``ple.biq`` (path "becots")."""
    from .biq import check_queries

    c, r = check_queries(centers, radii)
    if not is_becots(lat):  # U or V changed after set_becots (e.g. with_counts): the general path
        from .biq import _split as split_general
        from .rangefinder import lattice_hits

        nh, bh, path = lattice_hits(lat, c, r)
        return split_general(len(c), nh, bh, path)
    return query_subset(lat, c, r, None, None)


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
    info = becots_of(lat)
    lat.validate()
    node_ids = np.arange(len(lat.nodes)) if nodes is None else np.asarray(nodes, dtype=np.int64)
    beam_ids = np.arange(len(lat.beams)) if beams is None else np.asarray(beams, dtype=np.int64)
    node_hits, beam_hits = [], []
    for k in range(lat.w.count):
        g = lat.placement if k == 0 else Similarity.from_matrix(lat.placement.matrix @ (lat.W ** k).matrix)
        fld = info.field.placed(g)
        tc = g.apply_points(lat.template_centers)
        tr = lat.template_radii * g.factor
        nh, bh = _hits(fld, info.counts, info.group_counts, tc, tr, node_ids,
                       [(p, lat.beams[p]) for p in beam_ids], c, r, select)
        nh[:, 3] = bh[:, 3] = k
        node_hits.append(nh)
        beam_hits.append(bh)
    return _split(len(c), np.concatenate(node_hits), np.concatenate(beam_hits))


def _split(q: int, node_hits: np.ndarray, beam_hits: np.ndarray) -> list:
    """Per-query sorted, de-duplicated BIQResults from hit rows (qid, i, j, k, x)."""
    from .biq import BIQResult

    parts = []
    for hits in (node_hits, beam_hits):
        if len(hits):
            order = np.lexsort(hits.T[::-1])
            hits = hits[order]
            keep = np.ones(len(hits), dtype=bool)
            keep[1:] = np.any(hits[1:] != hits[:-1], axis=1)  # branches may find a shape twice
            hits = hits[keep]
        parts.append((hits[:, 1:], np.searchsorted(hits[:, 0], np.arange(q + 1))))
    (nh, nb), (bh, bb) = parts
    return [BIQResult(nh[nb[t]:nb[t + 1]], bh[bb[t]:bb[t + 1]], "becots") for t in range(q)]


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
def _hits(fld: BeCOTSField, counts, group_counts, tc, tr, node_ids, beams, c, r, select=None):
    """Hit arrays (qid, i, j, k, x) for one placed field (k is filled in by the caller)."""
    nu, nv = counts
    gu, gv = group_counts
    co = _Coords(fld, counts)
    # template shapes: nodes first, then beams (from-group (0, 0) to (di, dj))
    n_nodes = len(node_ids)
    shape_lim = [(0, gu - 1, 0, gv - 1)] * n_nodes
    bstart, bend = [], []
    for _, b in beams:
        shape_lim.append((max(0, -b.di), min(gu, gu - b.di) - 1, max(0, -b.dj), min(gv, gv - b.dj) - 1))
        bstart.append((tc[b.n1], tr[b.n1]))
        end = fld.apply([b.di / nu], [b.dj / nv], tc[b.n2])[0]
        bend.append((end, tr[b.n2] * _factor(fld, b.di / nu, b.dj / nv)))
    lim = np.array(shape_lim, dtype=np.int64).reshape(-1, 4)
    if len(lim) == 0 or len(c) == 0:
        return np.zeros((0, 5), np.int64), np.zeros((0, 5), np.int64)
    nc, nr = tc[node_ids], tr[node_ids]
    shells = [co.ball_shell(nc, nr)]
    if beams:
        shells.append(co.beam_shell(*_stack(bstart), *_stack(bend)))
    s_lo, s_hi = (np.concatenate(x) for x in zip(*shells))
    q_lo, q_hi = co.ball_shell(c, r)
    if fld.kind == "translation":
        boxes = [co.affine_box(nc, nr)]
        if beams:
            sa, sb = co.affine_box(*_stack(bstart)), co.affine_box(*_stack(bend))
            boxes.append(np.stack([np.minimum(sa[:, 0], sb[:, 0]), np.maximum(sa[:, 1], sb[:, 1]),
                                   np.minimum(sa[:, 2], sb[:, 2]), np.maximum(sa[:, 3], sb[:, 3])], axis=1))
        shape_box = np.concatenate(boxes)
        qbox = co.affine_box(c, r)
        rows = np.arange(len(c))
    else:
        parts = [co.ball_polar(nc, nr)]
        if beams:
            (ca, ra), (cb, rb) = _stack(bstart), _stack(bend)
            parts.append(co.beam_polar(ca, ra, cb, rb))
        rho0, rho1, mid, half = (np.concatenate(x) for x in zip(*parts))
        shape_box = co.index_box(rho0, rho1, mid - half, mid + half)
        # the lattice's angle range: template shapes shifted by every group's angle step
        (_, wu), (_, wv) = fld.u, fld.v
        steps_u, steps_v = (gu - 1) * wu / nu, (gv - 1) * wv / nv
        th_lo = float((mid - half).min()) + min(0.0, steps_u) + min(0.0, steps_v)
        th_hi = float((mid + half).max()) + max(0.0, steps_u) + max(0.0, steps_v)
        q0, q1, qmid, qhalf = co.ball_polar(c, r)
        kmin = np.ceil((th_lo - (qmid + qhalf)) / TWO_PI).astype(np.int64)
        kmax = np.floor((th_hi - (qmid - qhalf)) / TWO_PI).astype(np.int64)
        nk = np.maximum(kmax - kmin + 1, 0)
        rows = np.repeat(np.arange(len(c)), nk)
        kk = kmin[rows] + (np.arange(len(rows)) - np.repeat(np.cumsum(nk) - nk, nk))
        lift = qmid[rows] + TWO_PI * kk
        qbox = co.index_box(q0[rows], q1[rows], lift - qhalf[rows], lift + qhalf[rows])
    # the shapes each row tests: all of them, or the query's own selection
    pick = np.arange(len(lim))[None] if select is None else np.asarray(select, dtype=np.int64)[rows]
    sb, sl = shape_box[pick], lim[pick]
    # translation RangeFinder per (row, shape): I = [ceil(c - b), floor(d - a)] ∩ limits
    i0 = np.maximum(sl[..., 0], np.ceil(qbox[:, None, 0] - sb[..., 1] - INDEX_SLACK))
    i1 = np.minimum(sl[..., 1], np.floor(qbox[:, None, 1] - sb[..., 0] + INDEX_SLACK))
    j0 = np.maximum(sl[..., 2], np.ceil(qbox[:, None, 2] - sb[..., 3] - INDEX_SLACK))
    j1 = np.minimum(sl[..., 3], np.floor(qbox[:, None, 3] - sb[..., 2] + INDEX_SLACK))
    # conical shell test: a query outside a shape's shell interval meets none of its copies
    apart = (q_hi[rows][:, None] < s_lo[pick]) | (s_hi[pick] < q_lo[rows][:, None])
    ni = np.where(apart, 0, np.maximum(i1 - i0 + 1, 0)).astype(np.int64)
    nj = np.maximum(j1 - j0 + 1, 0).astype(np.int64)
    cnt = (ni * nj).reshape(-1)
    flat = np.repeat(np.arange(cnt.size), cnt)
    off = np.arange(flat.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    njf = nj.reshape(-1)[flat]
    ci = i0.reshape(-1)[flat].astype(np.int64) + off // np.maximum(njf, 1)
    cj = j0.reshape(-1)[flat].astype(np.int64) + off % np.maximum(njf, 1)
    row, col = np.divmod(flat, ni.shape[1])
    shape = np.broadcast_to(pick, ni.shape)[row, col]
    qid = rows[row]
    x, y = ci / nu, cj / nv
    # exact tests: nodes
    is_node = shape < n_nodes
    sel = np.nonzero(is_node)[0]
    n_of = node_ids[shape[sel]]
    centers = fld.apply(x[sel], y[sel], tc[n_of])
    hit = ball_ball_interfere(centers, tr[n_of] * _factor(fld, x[sel], y[sel]), c[qid[sel]], r[qid[sel]])
    s = sel[hit]
    node_hits = np.stack([qid[s], ci[s], cj[s], np.zeros_like(s), node_ids[shape[s]]], axis=1)
    # exact tests: beams
    sel = np.nonzero(~is_node)[0]
    p_local = shape[sel] - n_nodes
    pats = np.array([(p, b.n1, b.n2, b.di, b.dj) for p, b in beams], dtype=np.int64).reshape(-1, 5)[p_local]
    xa, ya = x[sel], y[sel]
    xb, yb = (ci[sel] + pats[:, 3]) / nu, (cj[sel] + pats[:, 4]) / nv
    ca = fld.apply(xa, ya, tc[pats[:, 1]])
    cb = fld.apply(xb, yb, tc[pats[:, 2]])
    ra = tr[pats[:, 1]] * _factor(fld, xa, ya)
    rb = tr[pats[:, 2]] * _factor(fld, xb, yb)
    hit = ball_beam_interfere(c[qid[sel]], r[qid[sel]], ca, ra, cb, rb)
    s = sel[hit]
    beam_hits = np.stack([qid[s], ci[s], cj[s], np.zeros_like(s), pats[hit, 0]], axis=1)
    return node_hits.astype(np.int64).reshape(-1, 5), beam_hits.astype(np.int64).reshape(-1, 5)


def _factor(fld: BeCOTSField, x, y):
    if fld.kind != "cone":
        return np.ones_like(np.asarray(x, float))
    return np.exp(np.asarray(x, float) * fld.u[0] + np.asarray(y, float) * fld.v[0])


def _stack(pairs):
    return np.array([p[0] for p in pairs]).reshape(-1, 3), np.array([p[1] for p in pairs], dtype=float)
