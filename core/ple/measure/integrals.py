"""Area and volume of clean lattices from their hubs (thesis §2.1, §3.6–3.7, §6.1.4).

A hub is a node's ball with the halves of its incident beams, each beam cut by the radical
plane of its two balls. In a clean lattice hubs have disjoint interiors, so the lattice's
volume is the sum of hub volumes and its area the sum of hub areas without the cut disks.

Every half-beam is convex and contains the node's centre, so a hub is star-shaped and, with
R(ω) the exit distance along direction ω, Volume = ∫ R³/3 dω and Area = ∫ R² / (n·ω) dω over
non-cut surface. ``hub_measures`` (the reference, slow) integrates that on a cubed-sphere grid
refined at the pieces' edges. ``hub_measures_batch`` (used for lattices) writes R = max_b R_b
over the one-beam hubs ball ∪ half-beam b, whose measures are exact solids of revolution, so
only the overlap term ∫ (Σ_b f_b − f_max) dω needs quadrature; it is vectorized over many hubs
at once and refined per hub until two grids (n and 2n, turned) agree (tests: solids of
revolution, fine reference grids, Monte Carlo). Assumes neighbouring balls are disjoint.

The sum over hubs uses similarity: hubs that differ by a group similarity of factor f have
f² times the area and f³ times the volume (§3.6). Along every direction whose similarity
commutes with the later ones (always W, §6.1.4; also V when V and W commute; U as well when
it commutes with both, §3.7) the hubs of the interior indices are copies of one hub, so
their sum is a geometric series; boundary indices (where beams are missing, §3.8) are
measured separately. Hubs congruent after normalization by their group similarity (all
interior hubs of a translation lattice, say) are measured once; hubs differing only in which
beams are present share their ray casting. ``method="sum"`` adds every hub individually.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..algebra.elements import beam_distance
from ..algebra.series import geometric_sum
from ..algebra.similarity import Rotation
from ..errors import PleError
from ..model.lattice import Lattice
from ..queries.overlaps import similar_axes

HUB_GRID = 24  # direction cells per cube face side (6 faces), edge cells refined REFINE × REFINE
REFINE = 8
MAX_HUBS = 200_000  # more hub classes than this: no area/volume (guard for huge base slabs)
MAX_KEPT_NODES = 20_000_000  # nodes of a filtered lattice or region decided one by one for its measures
GRID_START, GRID_MAX = 8, 64  # fast path: overlap quadrature cells per cube face side, first and last
FEATURE_CELLS = 2  # first grid: cells per narrowest angle between two beams of the hub
ADAPT_TOL = 3e-4  # refine while the overlap integrals on grids n and 2n (turned) differ by more than this × the measure


@dataclass
class HalfBeam:
    """The half of beam hull(ball(a, ra), ball(b, rb)) on a's side of the radical plane,
    in coordinates centred on a: ``offset`` = b - a."""

    offset: np.ndarray
    ra: float
    rb: float


def hub_measures(radius: float, half_beams: list[HalfBeam], grid: int = HUB_GRID) -> tuple[float, float]:
    """(area, volume) of the hub ball(0, radius) ∪ half-beams, by quadrature over directions.

    Directions form a cubed-sphere grid: on each of the 6 faces of the cube [-1, 1]³,
    ``grid`` × ``grid`` cells in (u, v), with solid angle dΩ = du dv / (1 + u² + v²)^1.5.
    Each cell is integrated by 2×2 Gauss points; cells whose 3×3 neighbourhood on the face
    shows more than one bounding surface piece (kinks, cut-disk edges) are re-sampled with
    REFINE × REFINE midpoint sub-cells."""
    n = grid
    h = 2.0 / n
    centre = -1 + (np.arange(n) + 0.5) * h
    g = np.array([-0.5, 0.5]) / math.sqrt(3.0) * h
    gu = (centre[:, None, None, None] + g[None, None, :, None]) + 0 * centre[None, :, None, None]
    gv = (centre[None, :, None, None] + g[None, None, None, :]) + 0 * centre[:, None, None, None]
    gu, gv = (x.reshape(-1) for x in np.broadcast_arrays(gu, gv))
    area = volume = 0.0
    k = REFINE
    off = ((np.arange(k) + 0.5) / k - 0.5) * h
    for face in _FACES:
        f_area, f_vol, label = _hub_integrands(radius, half_beams, _face_directions(face, gu, gv))
        jac = _jacobian(gu, gv) * (h * h / 4)
        fa, fv = (f_area * jac).reshape(n, n, 4).sum(axis=2), (f_vol * jac).reshape(n, n, 4).sum(axis=2)
        label = label.reshape(n, n, 4)
        lo, hi = label.min(axis=2), label.max(axis=2)
        lo, hi = _window(lo, np.minimum), _window(hi, np.maximum)
        edge = lo != hi
        area += float(fa[~edge].sum())
        volume += float(fv[~edge].sum())
        eu, ev = np.nonzero(edge)
        if len(eu):
            su = (centre[eu][:, None, None] + off[None, :, None]).repeat(k, axis=2).reshape(-1)
            sv = (centre[ev][:, None, None] + off[None, None, :]).repeat(k, axis=1).reshape(-1)
            a, v, _ = _hub_integrands(radius, half_beams, _face_directions(face, su, sv))
            jac = _jacobian(su, sv) * (h * h / (k * k))
            area += float(np.sum(a * jac))
            volume += float(np.sum(v * jac))
    for b in range(len(half_beams)):
        area += _visible_cone_area(half_beams, b, grid)
    return area, volume


def _visible_cone_area(half_beams: list[HalfBeam], b: int, grid: int) -> float:
    """Area of half-beam b's cone surface (contact circle on the node's ball to the cut)
    that no other half-beam covers: analytic frustum area minus the covered part, found on
    a (x, φ) grid refined where coverage changes."""
    hb = half_beams[b]
    d = np.asarray(hb.offset, float)
    length = float(np.linalg.norm(d))
    ra, rb = hb.ra, hb.rb
    if length + rb <= ra or length + ra <= rb:  # special case: no cone (one ball contains the other)
        return 0.0
    e = d / length
    s = (ra - rb) / length
    c = math.sqrt(1 - s * s)
    x0, x1 = ra * s, (length * length + ra * ra - rb * rb) / (2 * length)
    rho = lambda x: (ra - s * x) / c  # noqa: E731 - cone radius at axial position x
    full = math.pi * (rho(x0) + rho(x1)) * (x1 - x0) / c
    others = [h for i, h in enumerate(half_beams) if i != b]
    if not others:
        return full
    e1 = np.cross(e, [1.0, 0, 0] if abs(e[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e, e1)
    nx, nphi = max(grid // 2, 4), grid
    hx, hphi = (x1 - x0) / nx, 2 * math.pi / nphi

    def covered(x, phi):
        r = rho(x)
        p = x[:, None] * e + r[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
        inside = np.zeros(len(x), bool)
        for h in others:
            hl = float(np.linalg.norm(h.offset))
            he = np.asarray(h.offset, float) / hl
            cut = (hl * hl + h.ra * h.ra - h.rb * h.rb) / (2 * hl)
            along = p @ he
            # beam points outside the node's ball lie at along >= ra·s (here p is outside it)
            sel = np.nonzero(~inside & (along < cut) & (along >= h.ra * min((h.ra - h.rb) / hl, 0.0) - 1e-12))[0]
            if len(sel):
                inside[sel] = beam_distance(p[sel], np.zeros(3), h.ra, h.offset, h.rb) < -1e-12 * hl
        return inside, r / c  # dA = ρ dφ dx / c

    xc = x0 + (np.arange(nx) + 0.5) * hx
    pc = (np.arange(nphi) + 0.5) * hphi
    xx, pp = (a.reshape(-1) for a in np.meshgrid(xc, pc, indexing="ij"))
    inside, weight = covered(xx, pp)
    lab = inside.reshape(nx, nphi).astype(np.int64)
    lo = _window(np.minimum(lab, np.roll(lab, 1, 1), out=None), np.minimum)
    hi = _window(np.maximum(lab, np.roll(lab, 1, 1)), np.maximum)
    lo, hi = np.minimum(lo, np.roll(lo, -1, 1)), np.maximum(hi, np.roll(hi, -1, 1))
    edge = (lo != hi).reshape(-1)
    hidden = float(np.sum((inside * weight)[~edge])) * hx * hphi
    if edge.any():
        k = REFINE
        off = (np.arange(k) + 0.5) / k - 0.5
        sx = (xx[edge][:, None, None] + off[None, :, None] * hx).repeat(k, axis=2).reshape(-1)
        sp = (pp[edge][:, None, None] + off[None, None, :] * hphi).repeat(k, axis=1).reshape(-1)
        inside, weight = covered(sx, sp)
        hidden += float(np.sum(inside * weight)) * hx * hphi / (k * k)
    return full - hidden


_FACES = [(np.array(a, float), np.array(b, float), np.array(c, float)) for a, b, c in (
    ((1, 0, 0), (0, 1, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
    ((0, 1, 0), (0, 0, 1), (1, 0, 0)), ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
    ((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (0, 1, 0), (1, 0, 0)))]


def _face_directions(face, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    a, b, c = face
    d = a[None] + u[:, None] * b[None] + v[:, None] * c[None]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _jacobian(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Solid angle per unit du dv on a cube face (gnomonic projection)."""
    return (1 + u * u + v * v) ** -1.5


def _window(x: np.ndarray, op) -> np.ndarray:
    """op (min or max) over each cell's 3×3 neighbourhood on a face (clamped at its border)."""
    x = op.reduce([x, np.vstack([x[:1], x[:-1]]), np.vstack([x[1:], x[-1:]])])
    return op.reduce([x, np.hstack([x[:, :1], x[:, :-1]]), np.hstack([x[:, 1:], x[:, -1:]])])


def _directions(z: np.ndarray, phi: np.ndarray) -> np.ndarray:
    rho = np.sqrt(np.maximum(1 - z * z, 0.0))
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def _hub_integrands(radius: float, half_beams: list[HalfBeam], w: np.ndarray):
    """Per direction: area integrand of the node's visible ball (r² where the ball bounds
    the hub, else 0), volume integrand R³/3, and the label of the bounding surface piece
    (0: the node's ball; 4b + 1, 2, 3: half-beam b's cone, far ball, cut)."""
    best = np.full(len(w), float(radius))
    cosine = np.ones(len(w))  # n·ω at the exit point (ball: 1)
    label = np.zeros(len(w), np.int64)
    for b, hb in enumerate(half_beams):
        # beam points outside ball A have x >= ra·s along the axis, so only directions with
        # μ >= min(s, 0) can leave the hub through this half-beam
        length = float(np.linalg.norm(hb.offset))
        mu = w @ (np.asarray(hb.offset, float) / length)
        sel = np.nonzero(mu >= min((hb.ra - hb.rb) / length, 0.0) - 1e-12)[0]
        t, cos_n, piece = _half_beam_exit(w[sel], hb)
        better = t > best[sel]
        idx = sel[better]
        best[idx], cosine[idx], label[idx] = t[better], cos_n[better], 4 * b + piece[better]
    f_area = np.where(label == 0, radius * radius, 0.0)  # the visible part of the node's ball
    return f_area, best ** 3 / 3, label


def _half_beam_exit(w: np.ndarray, hb: HalfBeam):
    """Exit distance along unit directions w (n, 3) from a's centre, n·ω there, and the
    piece it lies on: 0 ball A, 1 lateral cone, 2 ball B, 3 the radical-plane cut."""
    d = np.asarray(hb.offset, float)
    length = float(np.linalg.norm(d))
    ra, rb = hb.ra, hb.rb
    e = d / length
    mu = w @ e
    nu = np.sqrt(np.maximum(1 - mu * mu, 0.0))
    t = np.full(len(w), ra)
    cos_n = np.ones(len(w))
    piece = np.zeros(len(w), np.int64)
    # ball B: far root of |tω - d|² = rb²
    beta = w @ d
    disc = beta * beta - length * length + rb * rb
    tb = np.where(disc >= 0, beta + np.sqrt(np.maximum(disc, 0)), -np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        nb = (tb[:, None] * w - d) / rb
        cos_b = np.sum(nb * w, axis=1)
    if length + rb <= ra:  # special case: ball A contains ball B, the beam is ball A
        return t, cos_n, piece
    use = tb > t
    t, cos_n, piece = np.where(use, tb, t), np.where(use, cos_b, cos_n), np.where(use, 2, piece)
    if length + ra > rb:  # lateral cone surface s x + c y = ra between the contact circles
        s = (ra - rb) / length
        c = math.sqrt(1 - s * s)
        den = s * mu + c * nu
        with np.errstate(divide="ignore", invalid="ignore"):
            tl = np.where(den > 0, ra / den, -np.inf)
        x = tl * mu
        ok = (x >= ra * s) & (x <= length + rb * s)
        tl = np.where(ok, tl, -np.inf)
        use = tl > t
        t, cos_n, piece = np.where(use, tl, t), np.where(use, den, cos_n), np.where(use, 1, piece)
    # the radical plane x = (L² + ra² - rb²) / 2L cuts the beam
    x_cut = (length * length + ra * ra - rb * rb) / (2 * length)
    with np.errstate(divide="ignore"):
        tp = np.where(mu > 0, x_cut / np.where(mu > 0, mu, 1.0), np.inf)
    cut = tp < t
    return np.where(cut, tp, t), cos_n, np.where(cut, 3, piece)


# ----- hubs of a lattice ------------------------------------------------------------------------------
def _incident(lat: Lattice):
    """Per template node: list of (pattern offset (3,), partner node, outgoing?)."""
    out = [[] for _ in lat.nodes]
    for b in lat.beams:
        out[b.n1].append((np.array(b.offset), b.n2, True))
        out[b.n2].append((-np.array(b.offset), b.n1, False))
    return out


def _segments(count: int, reach: int, similar: bool):
    """Index segments (start, stop, representative) along one direction: boundary indices
    one by one, the interior (where every beam-pattern's partner exists) as one segment
    when hubs along this direction are similar copies of each other."""
    if not similar or count <= 2 * reach + 1:
        return [(i, i + 1, i) for i in range(count)]
    segs = [(i, i + 1, i) for i in range(reach)]
    segs.append((reach, count - reach, reach))
    segs += [(i, i + 1, i) for i in range(count - reach, count)]
    return segs


def _series(s: float, power: int, start: int, stop: int, rep: int) -> float:
    """Σ_{i=start}^{stop-1} s^(power (i - rep)) in closed form (§3.6)."""
    q = s ** power
    return geometric_sum(q, stop - start, q ** (start - rep))


def _similar_axes(lat: Lattice) -> tuple[bool, bool, bool]:
    """Directions along which hubs (of equal beam presence) are similar copies (``similar_axes``)."""
    return similar_axes(lat)


def _rep_hubs(lat: Lattice, segs):
    """Representative hubs of every segment box: indices (H, 4) and per-hub area/volume series
    weights (the §3.6 sums over the segment box of s^2 and s^3 powers)."""
    s = (lat.U.factor, lat.V.factor, lat.W.factor)
    reps, wa, wv = [], [], []
    for d in range(3):
        reps.append(np.array([g[2] for g in segs[d]]))
        wa.append(np.array([_series(s[d], 2, *g) for g in segs[d]]))
        wv.append(np.array([_series(s[d], 3, *g) for g in segs[d]]))
    nn = len(lat.nodes)
    grids = np.meshgrid(np.arange(len(segs[0])), np.arange(len(segs[1])), np.arange(len(segs[2])), np.arange(nn),
                        indexing="ij")
    a, b, c, n = (x.reshape(-1) for x in grids)
    idx = np.stack([reps[0][a], reps[1][b], reps[2][c], n], axis=1)
    return idx, wa[0][a] * wa[1][b] * wa[2][c], wv[0][a] * wv[1][b] * wv[2][c]


def incidence_table(lat: Lattice):
    """Per template node, its half-beam slots: partner group offsets (nn, B, 3), partner nodes
    (nn, B) and which slots exist (nn, B) — the column order of every hub's half-beams."""
    incident = _incident(lat)
    nb = max(1, max(len(x) for x in incident))
    offs = np.zeros((len(lat.nodes), nb, 3), np.int64)
    partner = np.zeros((len(lat.nodes), nb), np.int64)
    valid = np.zeros((len(lat.nodes), nb), bool)
    for n, lst in enumerate(incident):
        for b, (off, p, _) in enumerate(lst):
            offs[n, b], partner[n, b], valid[n, b] = off, p, True
    return offs, partner, valid


def _hub_geometry(lat: Lattice, idx: np.ndarray, box=None, partners: bool = False):
    """Per hub (H rows of (i, j, k, n)): its node radius, partner offsets (H, B, 3) and radii
    (H, B) in the hub's own group frame (divided by the group's factor), presence mask (H, B)
    and the group factor (H,); with ``partners``, also the partners' indices (H, B, 4). Absent
    partners (outside the lattice, or outside ``box`` = (lo (3,), hi (3,)) half-open index
    bounds when given) are extrapolated and masked."""
    offs, partner, valid = incidence_table(lat)
    nb = offs.shape[1]
    n = idx[:, 3]
    pidx = idx[:, None, :3] + offs[n]  # (H, B, 3)
    lo, hi = (np.zeros(3, np.int64), np.array(lat.counts)) if box is None else box
    present = valid[n] & np.all((pidx >= lo) & (pidx < hi), axis=2)
    allidx = np.concatenate([idx[:, None, :], np.concatenate([pidx, partner[n][..., None]], axis=2)], axis=1)
    c, r = lat.node_balls(allidx.reshape(-1, 4))
    c, r = c.reshape(len(idx), nb + 1, 3), r.reshape(len(idx), nb + 1)
    m = lat.group_matrices(idx[:, 0], idx[:, 1], idx[:, 2])
    f = lat.group_factors(idx[:, 0], idx[:, 1], idx[:, 2])
    lin = m[:, :3, :3] / f[:, None, None]
    # back into the template frame: rotation transpose, divided by the factor
    local = np.einsum("hpa,hab->hpb", c - c[:, :1], lin) / f[:, None, None]
    rl = r / f[:, None]
    if partners:
        return rl[:, 0], local[:, 1:], rl[:, 1:], present & valid[n], f, allidx[:, 1:]
    return rl[:, 0], local[:, 1:], rl[:, 1:], present & valid[n], f


def lattice_measures(lat: Lattice, method: str = "closed", grid: int = 0, max_hubs: int = MAX_HUBS) -> dict:
    """{"area", "volume", "area_method", "hubs", "hub_shapes", ...} of a clean lattice.

    ``method="closed"``: geometric series along every direction where hubs are similar
    (§3.6, §3.7, §6.1.4); ``"sum"``: every hub measured and added (reference). Hubs congruent
    after normalization by their group similarity are measured once, all in one batch
    (``hub_measures_batch``; ``grid`` 0 = adaptive). Returns {"area_method": "skipped: ..."}
    without area/volume when more than ``max_hubs`` hubs would need measuring (a guard for
    huge base slabs, so that ``ple info`` stays bounded). A filtered lattice is measured by its
    kept hubs (``kept_measures``): the series assume every group's hubs are present."""
    lat.validate()
    if lat.filter is not None or lat.radius_field is not None:  # graded radii: no two hubs alike
        return kept_measures(lat, grid=grid)
    if lat.group_map is not None:  # groups not similar: every hub measured on its own
        if lat.node_count() > max_hubs:
            return {"area_method": f"skipped: {lat.node_count()} hubs of a {lat.group_map.kind} lattice "
                                   f"(limit {max_hubs})"}
        return dict(lattice_measures(lat.explicit(), "sum", grid, max_hubs), area_method="sum over hubs (per-hub path)")
    if method not in ("closed", "sum"):
        raise PleError(f"unknown area/volume method {method!r} (closed or sum)")
    reach = [max([abs(b.offset[d]) for b in lat.beams], default=0) for d in range(3)]
    similar = _similar_axes(lat) if method == "closed" else (False, False, False)
    segs = [_segments(c, rch, sim) for c, rch, sim in zip(lat.counts, reach, similar)]
    n_hubs = len(segs[0]) * len(segs[1]) * len(segs[2]) * len(lat.nodes)
    if n_hubs > max_hubs:
        return {"area_method": f"skipped: {n_hubs} hub classes to measure (limit {max_hubs})"}
    idx, wa, wv = _rep_hubs(lat, segs)
    ra, off, rb, present, f = _hub_geometry(lat, idx)
    area, volume, shapes, geometries = _measure_hubs(idx, ra, off, rb, present, f, wa, wv, grid)
    axes = "".join(name for name, sim in zip("UVW", similar) if sim)
    label = {"UVW": "closed form O(1) (§3.7)", "VW": "closed form O(ū) (§3.6)",
             "W": "closed form O(ūv̄) (§6.1.4)"}.get(axes, "sum over hubs")
    return {"area": area, "volume": volume, "area_method": label, "hubs": n_hubs, "hub_shapes": shapes,
            "hub_geometries": geometries, "hub_grid": grid or "adaptive"}


def _measure_hubs(idx, ra, off, rb, present, f, wa, wv, grid: int = 0) -> tuple[float, float, int, int]:
    """Σ weights × (f² area, f³ volume) of hubs given in their own frames. Hubs congruent after
    normalization share one geometry (all incident beams, absent partners extrapolated),
    measured once per subset of present beams. Returns area, volume, shapes, geometries."""
    if len(idx) == 0:
        return 0.0, 0.0, 0, 0
    key = np.round(np.concatenate([idx[:, 3:], ra[:, None], off.reshape(len(idx), -1), rb], axis=1), 9)
    key[key == 0] = 0.0  # -0.0 and 0.0 alike
    _, geo_first, geo = np.unique(key, axis=0, return_index=True, return_inverse=True)
    geo = geo.reshape(-1)
    _, first, inverse = np.unique(np.concatenate([geo[:, None], present], axis=1), axis=0, return_index=True,
                                  return_inverse=True)
    inverse = inverse.reshape(-1)
    g = geo_first
    a, v = hub_measures_batch(ra[g], off[g], rb[g], present[first], grid=grid, geometry=geo[first])
    return float(np.sum(a[inverse] * f * f * wa)), float(np.sum(v[inverse] * f**3 * wv)), len(first), len(g)


def kept_measures(lat: Lattice, region=None, grid: int = 0, max_nodes: int = MAX_KEPT_NODES) -> dict:
    """Area and volume of what a region of a (filtered) lattice keeps: every kept hub, with the
    half-beams to kept partners inside the region only (a removed node takes its beams with it,
    §9; a region's boundary cuts them). Streamed slab by slab; congruent hubs measured once.
    Returns {"area_method": "skipped: ..."} when the region holds more than ``max_nodes`` nodes."""
    lat.validate()
    r = lat.region(region)
    total = r.groups * len(lat.nodes)
    if total > max_nodes:
        return {"area_method": f"skipped: {total:,} nodes to decide one by one (limit {max_nodes:,}; "
                               "give a smaller --region)"}
    lo, hi = np.array([r.i0, r.j0, r.k0]), np.array([r.i1, r.j1, r.k1])
    area = volume = 0.0
    hubs = 0
    for _, ev in lat.iter_evaluation(r):
        idx = ev.node_index
        if not len(idx):
            continue
        ra, off, rb, present, f, partner = _hub_geometry(lat, idx, partners=True)
        inside = np.all((partner[..., :3] >= lo) & (partner[..., :3] < hi), axis=-1)
        present &= inside
        if lat.filter is not None and present.any():
            present[present] = lat.keeps(partner[present])
        ones = np.ones(len(idx))
        a, v, _, _ = _measure_hubs(idx, ra, off, rb, present, f, ones, ones, grid)
        area, volume, hubs = area + a, volume + v, hubs + len(idx)
    return {"area": area, "volume": volume, "area_method": "sum over kept hubs", "hubs": hubs,
            "hub_grid": grid or "adaptive"}


def lattice_volume(lat: Lattice) -> float | None:
    """Volume of a clean lattice (None when it has too many hubs to measure)."""
    return lattice_measures(lat).get("volume")


# ----- fast path: analytic single-beam hubs + a batched quadrature of their overlaps -------------------
def single_beam_excess(ra, rb, length):
    """(ΔA, ΔV) = measures of ball(0, ra) ∪ one half-beam minus those of the ball, exactly
    (a solid of revolution: ball A up to the contact circle x = ra·s, the cone frustum, ball
    B's zone past its contact circle if the radical plane lies beyond it; thesis §2.1)."""
    ra, rb, length = np.broadcast_arrays(*(np.asarray(x, float) for x in (ra, rb, length)))
    contained = length + rb <= ra  # special case: ball A contains ball B, the half-beam adds nothing
    safe = np.where(contained, 1.0, length)
    s = np.clip((ra - rb) / safe, -1.0, 1.0)
    c = np.sqrt(np.maximum(1 - s * s, 1e-300))
    x0 = ra * s
    x_cut = (safe * safe + ra * ra - rb * rb) / (2 * safe)
    x_b = safe + rb * s  # ball B's contact circle
    x1 = np.minimum(x_cut, x_b)
    r0, r1 = (ra - s * x0) / c, (ra - s * x1) / c
    area = 2 * math.pi * ra * ra * (1 + s) + math.pi * (r0 + r1) * (x1 - x0) / c
    volume = math.pi * (ra * ra * (x0 + ra) - (x0**3 + ra**3) / 3)  # ball A's segment up to the contact circle
    volume = volume + math.pi * (x1 - x0) * (r0 * r0 + r0 * r1 + r1 * r1) / 3  # the cone frustum
    u0, u1 = rb * s, np.maximum(x_cut - safe, rb * s)  # ball B's zone, in B's coordinate
    area = area + 2 * math.pi * rb * (u1 - u0)
    volume = volume + math.pi * (rb * rb * (u1 - u0) - (u1**3 - u0**3) / 3)
    d_area = np.where(contained, 0.0, area - 4 * math.pi * ra * ra)
    d_volume = np.where(contained, 0.0, volume - 4 / 3 * math.pi * ra**3)
    return d_area, d_volume


_DIRECTIONS: dict[tuple[int, bool], tuple[np.ndarray, np.ndarray]] = {}
_TURN = Rotation(1.0, [1.0, math.sqrt(2.0), math.pi], [0, 0, 0]).matrix[:3, :3]  # a generic rotation


def sphere_quadrature(n: int, turned: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Cubed-sphere directions (6 n², 3) and their solid-angle weights (sum 4π): n × n cells
    per cube face, one midpoint each, weight du dv / (1 + u² + v²)^1.5; ``turned``: the same
    grid under a fixed generic rotation (an independent second estimate)."""
    if (n, turned) not in _DIRECTIONS:
        h = 2.0 / n
        g = -1 + (np.arange(n) + 0.5) * h
        u, v = (x.reshape(-1) for x in np.meshgrid(g, g, indexing="ij"))
        dirs = np.concatenate([_face_directions(face, u, v) for face in _FACES])
        w = np.tile(_jacobian(u, v) * h * h, 6)
        _DIRECTIONS[n, turned] = (dirs @ _TURN.T if turned else dirs, w * (4 * math.pi / w.sum()))
    return _DIRECTIONS[n, turned]


def hub_measures_batch(ra, offsets, rb, present=None, grid: int = 0, geometry=None, chunk: int = 1 << 17):
    """(areas, volumes) of hubs: ball(0, ra[g]) ∪ half-beams towards offsets[g, b] (G, B, 3)
    with far radii rb[g, b]; ``present`` masks absent beams (padding). With ``geometry`` (V,)
    indices into the G geometries, ``present`` is (V, B) and each of the V results is that
    geometry with that subset of beams (boundary hubs share their geometry's ray casting).

    Exact single-beam excesses (``single_beam_excess``) plus the overlap of half-beams: the
    hub's radial function is R = max_b R_b (each ball ∪ half-beam is star-shaped from the
    centre), so V = V_ball + Σ ΔV_b − ∫ (Σ_b R_b³ − R³)/3 dω, and the same for the area with
    integrand R²/(n·ω) (0 on cut disks). Only that overlap integral, non-zero where two or more
    half-beams reach past the ball, uses quadrature (``sphere_quadrature(grid)``); grid 0 refines
    each geometry adaptively: grids n (from the narrowest beam angle, at least GRID_START) and 2n,
    alternately turned, until they agree to ADAPT_TOL of the measure (2n kept; n up to GRID_MAX)."""
    ra = np.asarray(ra, float)
    off = np.asarray(offsets, float).reshape(len(ra), -1, 3)
    rb = np.asarray(rb, float).reshape(off.shape[:2])
    vg = np.arange(len(ra)) if geometry is None else np.asarray(geometry, np.int64).reshape(-1)
    present = np.ones((len(vg), off.shape[1]), bool) if present is None else np.asarray(present, bool)
    length = np.linalg.norm(off, axis=2)
    safe = np.where(length > 0, length, 1.0)
    present = present & (length[vg] > 0)
    d_area, d_volume = single_beam_excess(ra[:, None], rb, safe)
    area = 4 * math.pi * ra[vg] ** 2 + np.sum(np.where(present, d_area[vg], 0.0), axis=1)
    volume = 4 / 3 * math.pi * ra[vg] ** 3 + np.sum(np.where(present, d_volume[vg], 0.0), axis=1)
    if off.shape[1] < 2:
        return area, volume
    e = off / safe[..., None]
    order = np.argsort(vg, kind="stable")
    vg, present = vg[order], present[order]
    rest = (ra, e, safe, rb, vg, present)
    if grid:
        ca, cv = _overlap_chunked(np.arange(len(ra)), rest, grid, chunk)
        area[order] -= ca
        volume[order] -= cv
        return area, volume
    # adaptive: each geometry's overlap integrals on two grids of n × n cells per face, the
    # second turned; their mean is kept when they agree to ADAPT_TOL of every variant's measure,
    # else n doubles (up to GRID_MAX)
    a_s, v_s = area[order], volume[order]
    # the first grid resolves the narrowest angle between two beams of a geometry (the overlap
    # lens of two beams is about that wide): cells of at most half that angle
    cosines = np.einsum("gbk,gck->gbc", e, e) - 2 * np.eye(e.shape[1])[None]
    closest = np.arccos(np.clip(cosines.max(axis=(1, 2)), -1.0, 1.0))
    start = np.clip(FEATURE_CELLS * (math.pi / 2) / np.maximum(closest, 1e-9), GRID_START, GRID_MAX)
    todo, n, waiting = np.zeros(0, np.int64), GRID_START, np.arange(len(ra))
    prev = None  # the finer grid of the last round (rows of ``todo``), reused as the coarse one
    while len(todo) or len(waiting):
        new = waiting[start[waiting] <= n]
        waiting = waiting[start[waiting] > n]
        if len(new):
            a0, v0 = _overlap_chunked(new, rest, n, chunk, turned=_turned(n))
            prev = _merge(todo, prev, new, (a0, v0), vg)
            todo = np.union1d(todo, new)
        if not len(todo):
            n *= 2
            continue
        rows = np.nonzero(np.isin(vg, todo))[0]
        a1, v1 = prev
        # the finer grid turned against the coarse one, so that their cells do not line up
        a2, v2 = _overlap_chunked(todo, rest, 2 * n, chunk, turned=_turned(2 * n))
        bad = (np.abs(a1 - a2) > ADAPT_TOL * a_s[rows]) | (np.abs(v1 - v2) > ADAPT_TOL * v_s[rows])
        bad_geo = np.zeros(len(ra), bool)
        bad_geo[vg[rows[bad]]] = 4 * n <= GRID_MAX
        ok = ~bad_geo[vg[rows]]
        a_s[rows[ok]] -= a2[ok]
        v_s[rows[ok]] -= v2[ok]
        todo, prev, n = todo[bad_geo[todo]], (a2[~ok], v2[~ok]), 2 * n
    area[order], volume[order] = a_s, v_s
    return area, volume


def _turned(n: int) -> bool:
    """Grids of successive refinement levels alternate between plain and turned."""
    return round(math.log2(n / GRID_START)) % 2 == 1


def _merge(todo, prev, new, values, vg):
    """Per-row values of the geometries todo ∪ new (rows sorted by geometry), from both parts."""
    if prev is None or not len(todo):
        return values
    rows_old, rows_new = np.nonzero(np.isin(vg, todo))[0], np.nonzero(np.isin(vg, new))[0]
    rows = np.concatenate([rows_old, rows_new])
    order = np.argsort(rows, kind="stable")
    return tuple(np.concatenate([p, q])[order] for p, q in zip(prev, values))


def _overlap_chunked(geos, rest, grid: int, chunk: int, turned: bool = False):
    """Overlap integrals of every variant (rows sorted by geometry) of the geometries ``geos``."""
    ra, e, length, rb, vg, present = rest
    dirs, weights = sphere_quadrature(grid, turned)
    per = max(1, chunk // (e.shape[1] * len(dirs)))
    out_a, out_v = [], []
    for lo in range(0, len(geos), per):
        g = geos[lo:lo + per]
        rows = np.nonzero(np.isin(vg, g))[0]
        local = np.searchsorted(g, vg[rows])
        a, v = _overlap_integrals(ra[g], e[g], length[g], rb[g], dirs, weights, local, present[rows])
        out_a.append(a)
        out_v.append(v)
    return np.concatenate(out_a), np.concatenate(out_v)


def beam_exits(ra, e, length, rb, dirs):
    """Per hub geometry g, half-beam b and direction m: the exit distance t (G, B, M) of ball(0, 1)
    ∪ half-beam b, in units of the node radius ra[g], and the area integrand R²/(n·ω) there
    (0 on the radical-plane cut disk), both float32. Shared by area/volume and the moments."""
    f32 = np.float32  # rays in single precision (1e-7 relative), sums in double
    lb = (length / ra[:, None])[..., None].astype(f32)  # (G, B, 1)
    rbb = (rb / ra[:, None])[..., None].astype(f32)
    s = np.clip((1 - rbb) / lb, -1.0, 1.0)
    c = np.sqrt(1 - s * s)
    x_cut = (lb * lb + 1 - rbb * rbb) / (2 * lb)  # the radical plane, beyond the ball (clean lattice)
    x_b = lb + rbb * s  # ball B's contact circle
    beam = lb + rbb > 1  # special case: a ball A containing ball B has no cone; the beam adds nothing
    mu = np.einsum("gbk,mk->gbm", e.astype(f32), dirs.astype(f32))
    den = c * np.sqrt(np.maximum(1 - mu * mu, 0.0))
    den += s * mu  # n·ω on the lateral cone s x + c y = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1 / den
    hit = (den > 0) & (mu >= s * den) & beam  # the cone, past the contact circle on ball A
    t = np.where(hit, inv, f32(1.0))
    f_area = np.where(hit, inv * inv * inv, f32(1.0))  # R² / (n·ω) = 1/den³ on the cone, 1 on the ball
    far = beam & (x_cut > x_b)  # special case: the radical plane lies past B's contact circle
    if far.any():  # ... so rays may leave through ball B: far root of |tω − d|² = rb², n·ω = sqrt(disc)/rb
        beta = mu * lb
        disc = beta * beta - (lb * lb - rbb * rbb)
        root = np.sqrt(np.maximum(disc, 0.0))
        tb = np.where((disc >= 0) & far, beta + root, -np.inf)
        onb = (tb > t) & ~(hit & (mu * t <= x_b))
        t = np.where(onb, tb, t)
        with np.errstate(divide="ignore", invalid="ignore"):
            f_area = np.where(onb, tb * tb * rbb / root, f_area)
        hit |= onb
    cut = hit & (mu * t > x_cut)  # the radical-plane disk: not surface of the lattice
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cut, x_cut / mu, t)
    f_area[cut] = 0.0
    return t, f_area


def _overlap_integrals(ra, e, length, rb, dirs, weights, vg, present):
    """∫ (Σ_b f_b − f_max) dω for area (f = R²/(n·ω), 0 on a cut) and volume (f = R³/3), per
    variant (geometry vg with beams ``present``). Computed in units of the node radius."""
    m = len(dirs)
    t, f_area = beam_exits(ra, e, length, rb, dirs)
    ia = f_area.reshape(-1, m) @ weights  # per-beam integrals (G·B,)
    iv = (t * t * t).reshape(-1, m) @ weights / 3
    # the variants: absent beams fall back to the ball (t = 1, f = 1); the bounding beam per direction
    tmax = np.ones((len(vg), m))
    famax = np.ones((len(vg), m))
    for b in range(t.shape[1]):
        tb_, better = t[vg, b], present[:, b:b + 1]
        better = better & (tb_ > tmax)
        tmax = np.where(better, tb_, tmax)
        famax = np.where(better, f_area[vg, b], famax)
    nb = present.sum(axis=1)
    sum_a = np.sum(np.where(present, ia.reshape(len(ra), -1)[vg], 0.0), axis=1)
    sum_v = np.sum(np.where(present, iv.reshape(len(ra), -1)[vg], 0.0), axis=1)
    over_a = sum_a - famax @ weights - (nb - 1) * 4 * math.pi
    over_v = sum_v - (tmax**3) @ weights / 3 - (nb - 1) * 4 * math.pi / 3
    r = ra[vg]
    return over_a * r * r, over_v * r**3
