"""Area and volume of clean lattices from their hubs (thesis §2.1, §3.6–3.7, §6.1.4).

A hub is a node's ball with the halves of its incident beams, each beam cut by the radical
plane of its two balls. In a clean lattice hubs have disjoint interiors, so the lattice's
volume is the sum of hub volumes and its area the sum of hub areas without the cut disks.

Every half-beam is convex and contains the node's centre, so a hub is star-shaped and, with
R(ω) the exit distance along direction ω, Volume = ∫ R³/3 dω and Area = ∫ R² / (n·ω) dω over
non-cut surface. ``hub_measures`` (the reference, slow) integrates that on a cubed-sphere grid
refined at the pieces' edges. ``hub_moments`` (the one hub routine for lattices: area and the
moment matrix, whose volume ``hub_measures_batch`` and ``lattice_measures`` read) writes
R = max_b R_b over the one-beam hubs ball ∪ half-beam b, whose measures are exact solids of
revolution, so only the overlap term ∫ (Σ_b f_b − f_max) dω needs quadrature; it is vectorized
over many hubs at once, on grids turned by pseudo-random rotations per hub geometry (unbiased,
so errors of distinct geometries cancel in a lattice's sum) and refined until the estimated
error of the lattice's sums is small (tests: solids of revolution, fine reference grids, Monte
Carlo). Assumes neighbouring balls are disjoint.

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
from ..errors import PleError, echo
from ..model.lattice import Lattice
from ..queries.overlaps import similar_axes

HUB_GRID = 24  # direction cells per cube face side (6 faces), edge cells refined REFINE × REFINE
REFINE = 8
MAX_HUBS = 200_000  # more hub classes than this: no area/volume (guard for huge base slabs)
MAX_KEPT_NODES = 20_000_000  # nodes of a filtered lattice or region decided one by one for its measures
GRID_START, GRID_MAX = 3, 48  # overlap quadrature cells per cube face side, first and last
ADAPT_TOL = 3e-4  # refine until 3 σ of the quadrature error of a lattice's summed measures is below this share
ROTATION_DOF = 32  # hub variants given extra rotations (a sample), and about the error estimate's degrees of freedom
ROTATIONS_MAX = 8  # rotations per sampled geometry: at most this many (at least 2)
CHUNK_RAYS = 1 << 20  # (geometry, half-beam, direction) rays per vectorized block
_GL = (np.array([-math.sqrt(0.6), 0.0, math.sqrt(0.6)]), np.array([5.0, 8.0, 5.0]) / 9.0)  # 3-point Gauss–Legendre


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


def row_segments(count: int, reach: int, similar: bool):
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


def rep_hubs(lat: Lattice, segs):
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


def hub_geometry(lat: Lattice, idx: np.ndarray, box=None, partners: bool = False):
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
        raise PleError(f"unknown area/volume method {echo(method)} (closed or sum)")
    reach = [max([abs(b.offset[d]) for b in lat.beams], default=0) for d in range(3)]
    similar = similar_axes(lat) if method == "closed" else (False, False, False)
    segs = [row_segments(c, rch, sim) for c, rch, sim in zip(lat.counts, reach, similar)]
    n_hubs = len(segs[0]) * len(segs[1]) * len(segs[2]) * len(lat.nodes)
    if n_hubs > max_hubs:
        return {"area_method": f"skipped: {n_hubs} hub classes to measure (limit {max_hubs})"}
    idx, wa, wv = rep_hubs(lat, segs)
    ra, off, rb, present, f = hub_geometry(lat, idx)
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
    _, geo_first, geo = unique_rows(key)
    _, first, inverse = unique_rows(np.concatenate([geo[:, None], present], axis=1).astype(np.float64))
    g = geo_first
    weights = np.zeros((len(first), 2))
    np.add.at(weights, inverse, np.stack([f * f * wa, f**3 * wv], axis=1))
    a, v = hub_measures_batch(ra[g], off[g], rb[g], present[first], grid=grid, geometry=geo[first], weights=weights)
    return float(np.sum(a[inverse] * f * f * wa)), float(np.sum(v[inverse] * f**3 * wv)), len(first), len(g)


def unique_rows(a: np.ndarray):
    """np.unique(a, axis=0) with index and inverse, through one byte string per row (faster)."""
    a = np.ascontiguousarray(a)
    rows = a.view(np.dtype((np.void, a.dtype.itemsize * a.shape[1]))).reshape(-1)
    u, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    return u, first, inverse.reshape(-1)


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
        ra, off, rb, present, f, partner = hub_geometry(lat, idx, partners=True)
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


_DIRECTIONS: dict[int, tuple[np.ndarray, np.ndarray]] = {}


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


def sphere_quadrature(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Cubed-sphere directions (6 n², 3) and their solid-angle weights (sum 4π): n × n cells
    per cube face, one midpoint each, weight du dv / (1 + u² + v²)^1.5."""
    if n not in _DIRECTIONS:
        h = 2.0 / n
        g = -1 + (np.arange(n) + 0.5) * h
        u, v = (x.reshape(-1) for x in np.meshgrid(g, g, indexing="ij"))
        dirs = np.concatenate([_face_directions(face, u, v) for face in _FACES])
        w = np.tile(_jacobian(u, v) * h * h, 6)
        _DIRECTIONS[n] = (dirs, w * (4 * math.pi / w.sum()))
    return _DIRECTIONS[n]


# ----- moment matrices of simple solids (exact) ------------------------------------------------------
def ball_moments(radius) -> np.ndarray:
    """Moment matrices (…, 4, 4) of balls of ``radius`` centred at the origin (``moments``: P = ∫ h hᵀ dV)."""
    r = np.asarray(radius, float)
    out = np.zeros(r.shape + (4, 4))
    out[..., 3, 3] = 4 / 3 * math.pi * r**3
    for a in range(3):
        out[..., a, a] = 4 / 15 * math.pi * r**5
    return out


def axial_moments(e, volume, first, axial2, radial2) -> np.ndarray:
    """Moment matrix of a solid of revolution about the axis through the origin along unit ``e``
    (…, 3) from its volume, ∫ x dV, ∫ x² dV (x along e) and ∫ ρ² dV (ρ the distance to the axis)."""
    e = np.asarray(e, float)
    ee = e[..., :, None] * e[..., None, :]
    out = np.zeros(e.shape[:-1] + (4, 4))
    out[..., :3, :3] = axial2[..., None, None] * ee + (radial2 / 2)[..., None, None] * (np.eye(3) - ee)
    out[..., :3, 3] = first[..., None] * e
    out[..., 3, :3] = first[..., None] * e
    out[..., 3, 3] = volume
    return out


def _piece(lo, hi, y2, y4):
    """(∫ π y², ∫ π y² x, ∫ π y² x², ∫ π y⁴ / 2) dx over [lo, hi] for a profile given as functions
    y²(x), y⁴(x) (polynomials of degree ≤ 4 in x: 3-point Gauss–Legendre is exact)."""
    nodes, weights = _GL
    half, mid = (hi - lo) / 2, (hi + lo) / 2
    sums = [0.0, 0.0, 0.0, 0.0]
    for t, w in zip(nodes, weights):
        x = mid + half * t
        a, b = y2(x), y4(x)
        sums[0] = sums[0] + w * a
        sums[1] = sums[1] + w * a * x
        sums[2] = sums[2] + w * a * x * x
        sums[3] = sums[3] + w * b / 2
    return [math.pi * half * s for s in sums]


def single_beam_moments(ra, rb, length):
    """(volume, ∫x, ∫x², ∫ρ²) of the one-beam hub ball(0, ra) ∪ half-beam towards (length, 0, 0)
    (far radius rb, cut by the radical plane) minus those of the ball, exactly: the ball up to the
    contact circle, the cone frustum, ball B's zone when the cut lies past its contact circle
    (the same pieces as ``single_beam_excess``)."""
    ra, rb, length = np.broadcast_arrays(*(np.asarray(x, float) for x in (ra, rb, length)))
    contained = length + rb <= ra  # special case: ball A contains ball B, nothing is added
    safe = np.where(contained, 1.0, length)
    s = np.clip((ra - rb) / safe, -1.0, 1.0)
    c = np.sqrt(np.maximum(1 - s * s, 1e-300))
    x0 = ra * s
    x_cut = (safe * safe + ra * ra - rb * rb) / (2 * safe)
    x1 = np.minimum(x_cut, safe + rb * s)
    u0, u1 = rb * s, np.maximum(x_cut - safe, rb * s)  # ball B's zone in B's coordinate
    ball = _piece(-ra, x0, lambda x: ra * ra - x * x, lambda x: (ra * ra - x * x) ** 2)
    cone = _piece(x0, x1, lambda x: ((ra - s * x) / c) ** 2, lambda x: ((ra - s * x) / c) ** 4)
    zone = _piece(safe + u0, safe + u1, lambda x: rb * rb - (x - safe) ** 2, lambda x: (rb * rb - (x - safe) ** 2) ** 2)
    full = (4 / 3 * math.pi * ra**3, 0.0, 4 / 15 * math.pi * ra**5, 8 / 15 * math.pi * ra**5)
    return tuple(np.where(contained, 0.0, p + q + z - f) for p, q, z, f in zip(ball, cone, zone, full))


# ----- the one hub routine: exact one-beam hubs + the overlap quadrature, randomly rotated -------------
def hub_moments(ra, offsets, rb, present=None, geometry=None, grid: int = 0, weights=None):
    """(areas (V,), moment matrices (V, 4, 4), quadrature stats) of hub variants in their
    node-centred frames: ball(0, ra[g]) ∪ half-beams towards offsets[g, b] (G, B, 3) with far
    radii rb[g, b], variant v being geometry ``geometry[v]`` (default: one variant per geometry)
    with the half-beams ``present[v]`` (V, B). The volume is moments[:, 3, 3].

    Exact ball and one-beam parts (``single_beam_excess``, ``single_beam_moments``) minus the
    overlap of the half-beams ∫ (Σ_b f_b − f_max) dω with f = (R²/(n·ω), R³/3, R⁴/4 ω, R⁵/5 ω ωᵀ)
    (R the exit distance; a hub is star-shaped from its centre), on a cubed-sphere grid.

    ``grid`` > 0: that grid, unrotated (deterministic, for tests and references). ``grid`` 0:
    each geometry's grid is turned by K pseudo-random rotations (uniform on SO(3), seeded by the
    geometry's rounded numbers, so the same hub always gets the same ones): a randomly rotated
    rule is unbiased, so the errors of distinct geometries cancel in a lattice's sum instead of
    adding up. The K values are averaged and their spread estimates the error of the sum
    Σ_v weights[v] · measure[v] (``weights`` (V, 2): area and volume weights, e.g. f² and f³
    times a series; default 1); the grid doubles from GRID_START until 3 σ of both sums is at
    most ADAPT_TOL of them (or GRID_MAX)."""
    ra = np.asarray(ra, float).reshape(-1)
    off = np.asarray(offsets, float).reshape(len(ra), -1, 3)
    rb = np.asarray(rb, float).reshape(off.shape[:2])
    vg = np.arange(len(ra)) if geometry is None else np.asarray(geometry, np.int64).reshape(-1)
    present = np.ones((len(vg), off.shape[1]), bool) if present is None else np.asarray(present, bool)
    present = present.reshape(len(vg), off.shape[1])
    length = np.linalg.norm(off, axis=2)
    safe = np.where(length > 0, length, 1.0)
    present = present & (length[vg] > 0)
    e = off / safe[..., None]
    d_area, _ = single_beam_excess(ra[:, None], rb, safe)
    dv, d1, d2, dr = single_beam_moments(ra[:, None], rb, safe)
    excess = axial_moments(e, dv, d1, d2, dr)  # (G, B, 4, 4)
    area = 4 * math.pi * ra[vg] ** 2 + np.sum(np.where(present, d_area[vg], 0.0), axis=1)
    moments = ball_moments(ra[vg]) + np.einsum("vb,vbij->vij", present.astype(float), excess[vg])
    stats = {"quadrature_grid": None, "quadrature_rotations": 0, "quadrature_rel_error": 0.0}
    multi = present.sum(axis=1) >= 2
    if not multi.any():
        return area, moments, stats
    geos, local = np.unique(vg[multi], return_inverse=True)
    sub = (ra[geos], e[geos], safe[geos], rb[geos], local.reshape(-1), present[multi])
    if grid:
        oa, om = _overlaps(*sub, int(grid), None)
        stats.update(quadrature_grid=int(grid), quadrature_rotations=0)
    else:
        w = np.ones((len(vg), 2)) if weights is None else np.asarray(weights, float).reshape(len(vg), 2)
        base = (area[multi], moments[multi, 3, 3])
        oa, om, n, k, rel = _adaptive_overlaps(sub, (ra[geos], off[geos], rb[geos]), w[multi], base)
        stats.update(quadrature_grid=n, quadrature_rotations=k, quadrature_rel_error=rel)
    area[multi] -= oa
    moments[multi] -= om
    return area, moments, stats


def _adaptive_overlaps(sub, numbers, weights, base):
    """Overlaps on randomly rotated grids, refined until the weighted sums' error estimate is small.
    Every variant is measured under its geometry's first rotation; a sample of variants (all when
    there are few) under K − 1 more. Their spread gives the relative error of one rotated
    measurement; the sum's error adds the geometries' errors independently, each geometry's
    variants taken as fully correlated (they share its rotation)."""
    ra, e, length, rb, local, present = sub
    geos, nv = len(ra), len(local)
    sample = np.unique(np.linspace(0, nv - 1, min(nv, ROTATION_DOF)).astype(np.int64))
    k = int(np.clip(math.ceil(ROTATION_DOF / len(sample)) + 1, 2, ROTATIONS_MAX))
    rots = random_rotations(_geometry_keys(*numbers), k)  # (G, K, 3, 3)
    sg = local[sample]
    # rows: every variant with rotation 0, then the sampled variants with rotations 1 … K − 1
    geo_rows = np.concatenate([np.arange(geos), np.repeat(sg, k - 1)])
    rot_rows = np.concatenate([rots[:, 0], rots[sg, 1:].reshape(-1, 3, 3)])
    var_rows = np.concatenate([local, geos + np.arange(len(sample) * (k - 1))])
    var_present = np.concatenate([present, np.repeat(present[sample], k - 1, axis=0)])
    n = GRID_START
    while True:
        oa, om = _overlaps(ra[geo_rows], e[geo_rows], length[geo_rows], rb[geo_rows], var_rows, var_present, n,
                           rot_rows)
        rel = 0.0
        means = []
        for x, wcol, total in ((oa, weights[:, 0], base[0]), (om[:, 3, 3], weights[:, 1], base[1])):
            all_k = np.concatenate([x[:nv][sample][:, None], x[nv:].reshape(-1, k - 1)], axis=1)  # (S, K)
            measure = total - x[:nv]
            # special case: a hub its beams cover (nearly) wholly is weighed against 10⁻¹² of its
            # measure before the overlaps, not divided by zero
            scale = np.maximum(np.abs(measure[sample]), 1e-12 * np.abs(total[sample]))
            rel_var = float(np.mean((np.std(all_k, axis=1, ddof=1) / scale) ** 2))
            per_geo = np.zeros(geos)
            np.add.at(per_geo, local, wcol * measure)
            rel = max(rel, 3 * math.sqrt(rel_var * float(np.sum(per_geo**2))) / max(float(per_geo.sum()), 1e-300))
            means.append(all_k.mean(axis=1))
        area, mom = oa[:nv].copy(), om[:nv].copy()
        area[sample] = means[0]
        mom[sample] = np.concatenate([om[:nv][sample][:, None], om[nv:].reshape(-1, k - 1, 4, 4)], 1).mean(1)
        if rel <= ADAPT_TOL or 2 * n > GRID_MAX:
            return area, mom, n, k, rel
        n *= 2


def _geometry_keys(ra, off, rb) -> np.ndarray:
    """64-bit hashes (G,) of the geometries' numbers rounded to 1e-9 (splitmix64 over the bytes)."""
    key = np.round(np.concatenate([ra[:, None], off.reshape(len(ra), -1), rb], axis=1), 9)
    key[key == 0] = 0.0  # -0.0 and 0.0 alike
    h = np.full(len(ra), 0x9E3779B97F4A7C15, np.uint64)
    for col in np.ascontiguousarray(key).view(np.uint64).T:
        h = _splitmix(h ^ col)
    return h


def _splitmix(x: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        x = x + np.uint64(0x9E3779B97F4A7C15)
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def random_rotations(keys: np.ndarray, k: int) -> np.ndarray:
    """(G, k, 3, 3) rotations uniform on SO(3) (Shoemake's quaternions), a fixed function of ``keys``."""
    u = np.empty((len(keys), k, 3))
    with np.errstate(over="ignore"):
        for j in range(k):
            for c in range(3):
                bits = _splitmix(keys + np.uint64(3 * j + c + 1))
                u[:, j, c] = (bits >> np.uint64(11)).astype(float) / float(1 << 53)
    a, b = np.sqrt(1 - u[..., 0]), np.sqrt(u[..., 0])
    x, y = a * np.sin(2 * math.pi * u[..., 1]), a * np.cos(2 * math.pi * u[..., 1])
    z, w = b * np.sin(2 * math.pi * u[..., 2]), b * np.cos(2 * math.pi * u[..., 2])
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def _overlaps(ra, e, length, rb, vg, present, grid, rot):
    """Overlap ∫ (Σ_b f_b − f_max) dω per variant (geometry vg, half-beams ``present``) for the area
    integrand and the moment matrix; ``rot`` (G, 3, 3): each geometry's grid turned by it."""
    dirs, w = sphere_quadrature(grid)
    m, nb_max = len(dirs), e.shape[1]
    w1 = w[:, None] * dirs
    w2 = (w[:, None, None] * dirs[:, :, None] * dirs[:, None, :]).reshape(m, 9)
    ball = np.concatenate([np.eye(3).reshape(-1) * 4 * math.pi / 15, np.zeros(3), [4 * math.pi / 3]])
    unit_ball = np.concatenate([[4 * math.pi], ball])
    # the grid turned by R is the beams turned by Rᵀ
    e = e if rot is None else np.einsum("gbk,gkj->gbj", e, rot)

    def integrals(t, fa):  # (…, M) → (…, 14): area, second (9), first (3), volume, in node-radius units
        t3 = t * t * t
        return np.concatenate([(fa @ w)[..., None], (t3 * t * t) @ w2 / 5, (t3 * t) @ w1 / 4,
                               (t3 @ w / 3)[..., None]], axis=-1)

    out = np.zeros((len(vg), 14))
    order = np.argsort(vg, kind="stable")
    starts = np.searchsorted(vg[order], np.arange(len(ra) + 1))
    per = max(1, CHUNK_RAYS // (nb_max * m))
    for lo in range(0, len(ra), per):
        hi = min(len(ra), lo + per)
        rows = order[starts[lo]:starts[hi]]
        local = vg[rows] - lo
        t, fa = beam_exits(ra[lo:hi], e[lo:hi], length[lo:hi], rb[lo:hi], dirs)
        per_beam = integrals(t, fa)  # (G, B, 14)
        pres = present[rows]
        tmax = np.ones((len(rows), m), np.float32)
        famax = np.ones((len(rows), m), np.float32)
        for b in range(nb_max):
            tb = t[local, b]
            better = pres[:, b:b + 1] & (tb > tmax)
            tmax = np.where(better, tb, tmax)
            famax = np.where(better, fa[local, b], famax)
        nb = pres.sum(axis=1)
        total = np.einsum("vb,vbk->vk", pres.astype(float), per_beam[local])
        out[rows] = total - integrals(tmax, famax) - (nb - 1)[:, None] * unit_ball
    if rot is not None:  # back from the turned frame: second moment R S Rᵀ, first R v
        rv = rot[vg]
        out[:, 1:10] = np.einsum("vab,vbc,vdc->vad", rv, out[:, 1:10].reshape(-1, 3, 3), rv).reshape(-1, 9)
        out[:, 10:13] = np.einsum("vab,vb->va", rv, out[:, 10:13])
    r = ra[vg]
    mom = np.zeros((len(vg), 4, 4))
    mom[:, :3, :3] = out[:, 1:10].reshape(-1, 3, 3) * (r**5)[:, None, None]
    mom[:, :3, 3] = mom[:, 3, :3] = out[:, 10:13] * (r**4)[:, None]
    mom[:, 3, 3] = out[:, 13] * r**3
    return out[:, 0] * r**2, mom


def hub_measures_batch(ra, offsets, rb, present=None, grid: int = 0, geometry=None, weights=None):
    """(areas, volumes) of hubs (``hub_moments``: the same numbers as the moments)."""
    area, mom, _ = hub_moments(ra, offsets, rb, present, geometry, grid, weights)
    return area, mom[:, 3, 3]
