"""Area and volume of clean lattices from their hubs (thesis §2.1, §3.6–3.7, §6.1.4).

A hub is a node's ball with the halves of its incident beams, each beam cut by the radical
plane of its two balls. In a clean lattice hubs have disjoint interiors, so the lattice's
volume is the sum of hub volumes and its area the sum of hub areas without the cut disks.

One hub is measured by quadrature over directions from its node centre: every half-beam is
convex and contains the centre, so the hub is star-shaped and, with R(ω) the exit distance
along direction ω, Volume = ∫ R³/3 dω and Area = ∫ R² / (n·ω) dω over non-cut surface.
A cubed-sphere direction grid refined at the pieces' edges gives a few 1e-4 relative
error at worst (tests: analytic solids of revolution and Monte Carlo).

The sum over hubs uses similarity: hubs that differ by a group similarity of factor f have
f² times the area and f³ times the volume (§3.6). Along every direction whose similarity
commutes with the later ones (always W, §6.1.4; also V when V and W commute; U as well when
it commutes with both, §3.7) the hubs of the interior indices are copies of one hub, so
their sum is a geometric series; boundary indices (where beams are missing, §3.8) are
measured separately. ``method="sum"`` adds every hub individually (the plain sum).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .elements import beam_distance
from .errors import PleError
from .lattice import Lattice
from .similarity import Similarity

HUB_GRID = 24  # direction cells per cube face side (6 faces), edge cells refined REFINE × REFINE
REFINE = 8
MAX_HUBS = 200_000  # more hub classes than this: no area/volume (guard for huge base slabs)
GRID_START, GRID_MAX = 4, 128  # fast path: overlap quadrature cells per cube face side, first and last
ADAPT_TOL = 1e-3  # refine a hub while its overlap integrals at n and n/2 differ by more than this × its measure


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
    n = stop - start
    first = q ** (start - rep)
    if abs(q - 1.0) < 1e-15:
        return float(n)
    return first * (1 - q ** n) / (1 - q)


def _commutes(a: Similarity, b: Similarity) -> bool:
    ma, mb = a.matrix, b.matrix
    scale = max(1.0, np.abs(ma).max(), np.abs(mb).max()) ** 2
    return bool(np.abs(ma @ mb - mb @ ma).max() <= 1e-10 * scale)


def _similar_axes(lat: Lattice) -> tuple[bool, bool, bool]:
    """Directions along which hubs (of equal beam presence) are similar copies: W always;
    V if V and W commute; U if U commutes with V and W (or those are single)."""
    act = [c > 1 for c in lat.counts]
    vw = not (act[1] and act[2]) or _commutes(lat.V, lat.W)
    u = all(not (act[0] and act[x]) or _commutes(lat.U, s) for x, s in ((1, lat.V), (2, lat.W)))
    return u, vw, True


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


def _hub_geometry(lat: Lattice, idx: np.ndarray):
    """Per hub (H rows of (i, j, k, n)): its node radius, partner offsets (H, B, 3) and radii
    (H, B) in the hub's own group frame (divided by the group's factor), presence mask (H, B)
    and the group factor (H,). Absent partners are extrapolated and masked."""
    incident = _incident(lat)
    nb = max(1, max(len(x) for x in incident))
    offs = np.zeros((len(lat.nodes), nb, 3), np.int64)
    partner = np.zeros((len(lat.nodes), nb), np.int64)
    valid = np.zeros((len(lat.nodes), nb), bool)
    for n, lst in enumerate(incident):
        for b, (off, p, _) in enumerate(lst):
            offs[n, b], partner[n, b], valid[n, b] = off, p, True
    n = idx[:, 3]
    pidx = idx[:, None, :3] + offs[n]  # (H, B, 3)
    present = valid[n] & np.all((pidx >= 0) & (pidx < np.array(lat.counts)), axis=2)
    allidx = np.concatenate([idx[:, None, :], np.concatenate([pidx, partner[n][..., None]], axis=2)], axis=1)
    c, r = lat.node_balls(allidx.reshape(-1, 4))
    c, r = c.reshape(len(idx), nb + 1, 3), r.reshape(len(idx), nb + 1)
    m = lat.group_matrices(idx[:, 0], idx[:, 1], idx[:, 2])
    f = lat.group_factors(idx[:, 0], idx[:, 1], idx[:, 2])
    lin = m[:, :3, :3] / f[:, None, None]
    # back into the template frame: rotation transpose, divided by the factor
    local = np.einsum("hpa,hab->hpb", c - c[:, :1], lin) / f[:, None, None]
    rl = r / f[:, None]
    return rl[:, 0], local[:, 1:], rl[:, 1:], present & valid[n], f


def lattice_measures(lat: Lattice, method: str = "closed", grid: int = 0, max_hubs: int = MAX_HUBS) -> dict:
    """{"area", "volume", "area_method", "hubs", "hub_shapes", ...} of a clean lattice.

    ``method="closed"``: geometric series along every direction where hubs are similar
    (§3.6, §3.7, §6.1.4); ``"sum"``: every hub measured and added (reference). Hubs congruent
    after normalization by their group similarity are measured once, all in one batch
    (``hub_measures_batch``; ``grid`` 0 = adaptive). Returns {"area_method": "skipped: ..."}
    without area/volume when more than ``max_hubs`` hubs would need measuring (a guard for
    huge base slabs, so that ``ple info`` stays bounded)."""
    lat.validate()
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
    # congruent hubs after normalization: one geometry (all incident beams, absent partners
    # extrapolated), measured once per subset of present beams
    key = np.round(np.concatenate([idx[:, 3:], ra[:, None], off.reshape(len(idx), -1), rb], axis=1), 9)
    key[key == 0] = 0.0  # -0.0 and 0.0 alike
    _, geo_first, geo = np.unique(key, axis=0, return_index=True, return_inverse=True)
    geo = geo.reshape(-1)
    _, first, inverse = np.unique(np.concatenate([geo[:, None], present], axis=1), axis=0, return_index=True,
                                  return_inverse=True)
    inverse = inverse.reshape(-1)
    g = geo_first
    a, v = hub_measures_batch(ra[g], off[g], rb[g], present[first], grid=grid, geometry=geo[first])
    area = float(np.sum(a[inverse] * f * f * wa))
    volume = float(np.sum(v[inverse] * f**3 * wv))
    axes = "".join(name for name, sim in zip("UVW", similar) if sim)
    label = {"UVW": "closed form O(1) (§3.7)", "VW": "closed form O(ū) (§3.6)",
             "W": "closed form O(ūv̄) (§6.1.4)"}.get(axes, "sum over hubs")
    return {"area": area, "volume": volume, "area_method": label, "hubs": n_hubs, "hub_shapes": len(first),
            "hub_geometries": len(g),
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


def hub_measures_batch(ra, offsets, rb, present=None, grid: int = 0, geometry=None, chunk: int = 1 << 19):
    """(areas, volumes) of hubs: ball(0, ra[g]) ∪ half-beams towards offsets[g, b] (G, B, 3)
    with far radii rb[g, b]; ``present`` masks absent beams (padding). With ``geometry`` (V,)
    indices into the G geometries, ``present`` is (V, B) and each of the V results is that
    geometry with that subset of beams (boundary hubs share their geometry's ray casting).

    Exact single-beam excesses (``single_beam_excess``) plus the overlap of half-beams: the
    hub's radial function is R = max_b R_b (each ball ∪ half-beam is star-shaped from the
    centre), so V = V_ball + Σ ΔV_b − ∫ (Σ_b R_b³ − R³)/3 dω, and the same for the area with
    integrand R²/(n·ω) (0 on cut disks). Only that overlap integral, non-zero where two or more
    half-beams reach past the ball, uses quadrature (``sphere_quadrature(grid)``); grid 0 refines
    each geometry adaptively (GRID_START, doubling to GRID_MAX) until two grids agree to ADAPT_TOL."""
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
    # adaptive: halve the cell size of every geometry whose overlap integrals at n and n/2 differ
    # by more than ADAPT_TOL of a hub's measure (midpoint rule, error O(h²)); Richardson-extrapolate
    a_s, v_s = area[order], volume[order]
    todo = np.arange(len(ra))
    lo_a, lo_v = _overlap_chunked(todo, rest, GRID_START, chunk)
    n = 2 * GRID_START
    while len(todo):
        rows = np.nonzero(np.isin(vg, todo))[0]
        hi_a, hi_v = _overlap_chunked(todo, rest, n, chunk)
        bad = (np.abs(hi_a - lo_a) > ADAPT_TOL * a_s[rows]) | (np.abs(hi_v - lo_v) > ADAPT_TOL * v_s[rows])
        bad_geo = np.zeros(len(ra), bool)
        bad_geo[vg[rows[bad]]] = n < GRID_MAX
        ok = ~bad_geo[vg[rows]]
        a_s[rows[ok]] -= hi_a[ok] + (hi_a[ok] - lo_a[ok]) / 3
        v_s[rows[ok]] -= hi_v[ok] + (hi_v[ok] - lo_v[ok]) / 3
        todo, lo_a, lo_v, n = todo[bad_geo[todo]], hi_a[~ok], hi_v[~ok], 2 * n
    area[order], volume[order] = a_s, v_s
    return area, volume


def _overlap_chunked(geos, rest, grid: int, chunk: int):
    """Overlap integrals of every variant (rows sorted by geometry) of the geometries ``geos``."""
    ra, e, length, rb, vg, present = rest
    dirs, weights = sphere_quadrature(grid)
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


def _overlap_integrals(ra, e, length, rb, dirs, weights, vg, present):
    """∫ (Σ_b f_b − f_max) dω for area (f = R²/(n·ω), 0 on a cut) and volume (f = R³/3), per
    variant (geometry vg with beams ``present``)."""
    ra3 = ra[:, None, None]
    s = np.clip((ra[:, None] - rb) / length, -1.0, 1.0)[..., None]
    c = np.sqrt(np.maximum(1 - s * s, 0.0))
    mu = np.einsum("hbk,mk->hbm", e, dirs)
    nu = np.sqrt(np.maximum(1 - mu * mu, 0.0))
    lb, rbb = length[..., None], rb[..., None]
    # ball B: far root of |tω − d|² = rb², n·ω = sqrt(disc) / rb
    beta = mu * lb
    disc = beta * beta - (lb * lb - rbb * rbb)
    root = np.sqrt(np.maximum(disc, 0.0))
    t = np.where(disc >= 0, beta + root, -np.inf)
    cos = root / np.where(rbb > 0, rbb, 1.0)
    # lateral cone s x + c y = ra between the contact circles, n·ω = s μ + c ν
    den = s * mu + c * nu
    with np.errstate(divide="ignore", invalid="ignore"):
        tl = np.where(den > 0, ra3 / den, -np.inf)
    x = tl * mu
    tl = np.where((x >= ra3 * s) & (x <= lb + rbb * s) & (lb + ra3 > rbb), tl, -np.inf)
    use = tl > t
    t, cos = np.where(use, tl, t), np.where(use, den, cos)
    ball = ~(t > ra3) | (lb + rbb <= ra3)
    t = np.where(ball, ra3, t)
    with np.errstate(divide="ignore", invalid="ignore"):
        f_area = np.where(ball, ra3 * ra3, t * t / cos)
        x_cut = ((lb * lb + ra3 * ra3 - rbb * rbb) / (2 * lb))
        tp = np.where(mu > 0, x_cut / np.where(mu > 0, mu, 1.0), np.inf)
    cut = ~ball & (tp < t)
    t = np.where(cut, tp, t)
    f_area = np.where(cut, 0.0, f_area)
    # the variants: absent beams fall back to the ball
    rv = ra[vg][:, None, None]
    keep = present[..., None]
    t = np.where(keep, t[vg], rv)
    f_area = np.where(keep, f_area[vg], rv * rv)
    ra = ra[vg]
    f_vol = t**3 / 3
    best = np.argmax(t, axis=1)[:, None]
    over_a = f_area.sum(axis=1) - np.take_along_axis(f_area, best, axis=1)[:, 0] - (e.shape[1] - 1) * ra[:, None] ** 2
    over_v = f_vol.sum(axis=1) - np.take_along_axis(f_vol, best, axis=1)[:, 0] - (e.shape[1] - 1) * ra[:, None] ** 3 / 3
    return over_a @ weights, over_v @ weights
