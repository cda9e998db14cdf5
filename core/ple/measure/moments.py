"""Integral properties of lattices, index regions and filtered lattices: area, volume, centroid and
inertia tensor (thesis §3.6–3.7, §6.1.4, extended from area and volume to moments).

Every moment of a solid up to order two sits in one symmetric 4×4 *moment matrix*
P = ∫ h hᵀ dV with h = (x, 1): P[3, 3] is the volume, P[:3, 3] the first moment, P[:3, :3] the
second moment about the origin. A similarity x ↦ A x + t of factor s (homogeneous matrix M)
maps it to s³ M P Mᵀ: volume × s³, first moment × s⁴ moved rigidly, second × s⁵ — one linear map
of P, so the §3.6 geometric series over a steady row become operator series
Σ_d (s³ M ⊗ M)^d (``algebra.series.operator_geometric_sum``).

A lattice is the union of its hubs (``integrals``: a node's ball with the halves of its beams,
cut by radical planes); in a clean lattice they have disjoint interiors, so P is the sum of hub
moment matrices. A hub's P is exact for the ball and each one-beam hub ball ∪ half-beam (a solid
of revolution, integrated piecewise by 3-point Gauss–Legendre, exact for its degree-4
polynomials), minus the overlap of the half-beams ∫ (Σ_b f_b − f_max) dω with
f = (R³/3, R⁴/4 ω, R⁵/5 ω ωᵀ) on a cubed-sphere grid (``integrals.beam_exits``, the same rays
as the area and volume). Hubs that are similar copies (after normalization by their group
similarity) share one measurement.

Unfiltered lattices and regions: the interior segments of the similar directions (as in
``integrals.lattice_measures``) are summed by operator series; filtered lattices (``lat.filter``):
every kept hub is added, with the beams whose two ends are kept, hub shapes shared by
(geometry, kept beams). The overlap quadrature grid is chosen from a budget of rays, and its
error is estimated on a sample of hubs re-measured on a twice finer grid.
"""

from __future__ import annotations

import math

import numpy as np

from ..algebra.series import operator_geometric_sum
from ..errors import PleError
from ..model.lattice import Lattice
from ..queries.overlaps import reach, similar_axes
from ..queries.plans import lattice_key
from .integrals import (
    MAX_HUBS,
    _hub_geometry,
    _segments,
    beam_exits,
    incidence_table,
    single_beam_excess,
    sphere_quadrature,
)

RAY_BUDGET = 3_000_000  # (hub geometry, half-beam, direction) rays of the overlap quadrature per call
GRID_FINE, GRID_MIN = 16, 3  # overlap quadrature cells per cube-face side: wanted, and the least
ERROR_SAMPLE = 64  # hub geometries re-measured on a twice finer grid to estimate the quadrature error
CHUNK_RAYS = 1 << 20  # rays per vectorized block
HUB_CHUNK = 1 << 16  # kept hubs per block of the per-hub sums
MAX_KEPT_NODES = 20_000_000  # filtered lattices are evaluated in full; beyond this, no moments
CACHE_ATTR = "_mass_properties"
_GL = (np.array([-math.sqrt(0.6), 0.0, math.sqrt(0.6)]), np.array([5.0, 8.0, 5.0]) / 9.0)


# ----- moment matrices of simple solids --------------------------------------------------------------
def ball_moments(radius) -> np.ndarray:
    """Moment matrices (…, 4, 4) of balls of ``radius`` centred at the origin."""
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
    (the same pieces as ``integrals.single_beam_excess``)."""
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


def transform(moments: np.ndarray, matrix: np.ndarray, factor) -> np.ndarray:
    """Moment matrices under similarities: s³ M P Mᵀ (broadcast over leading axes)."""
    f3 = np.asarray(factor, float) ** 3
    return f3[..., None, None] * (matrix @ moments @ np.swapaxes(matrix, -1, -2))


def series_operator(matrix: np.ndarray, factor: float, n: int) -> np.ndarray:
    """(16, 16): Σ_{d<n} L^d for L(P) = s³ M P Mᵀ on row-major flattened P (§3.6 for moments)."""
    return operator_geometric_sum(factor**3 * np.kron(matrix, matrix), n)


def summary(moments: np.ndarray, area: float) -> dict:
    """area, volume, centroid (3,), inertia (3, 3) about the centroid (unit density:
    ∫ (|r|² I − r rᵀ) dV) and the second moment ∫ r rᵀ dV about the centroid, from a moment matrix."""
    volume = float(moments[3, 3])
    if volume <= 0:
        return {"area": float(area), "volume": 0.0, "centroid": None, "inertia": None, "second_moment": None}
    c = moments[:3, 3] / volume
    second = moments[:3, :3] - volume * np.outer(c, c)
    second = (second + second.T) / 2
    inertia = np.trace(second) * np.eye(3) - second
    return {"area": float(area), "volume": volume, "centroid": c.tolist(), "inertia": inertia.tolist(),
            "second_moment": second.tolist()}


# ----- hubs ----------------------------------------------------------------------------------------
def hub_moments(ra, offsets, rb, present, geometry, grid: int, turned: bool = False):
    """(areas (V,), moment matrices (V, 4, 4)) of hub variants in their node-centred frames: geometry
    ``geometry[v]`` (rows of ra (G,), offsets (G, B, 3), rb (G, B)) with the half-beams ``present``
    (V, B). Exact ball and one-beam parts minus the overlap quadrature on ``grid``."""
    ra = np.asarray(ra, float)
    off = np.asarray(offsets, float).reshape(len(ra), -1, 3)
    rb = np.asarray(rb, float).reshape(off.shape[:2])
    vg = np.asarray(geometry, np.int64).reshape(-1)
    length = np.linalg.norm(off, axis=2)
    safe = np.where(length > 0, length, 1.0)
    present = np.asarray(present, bool) & (length[vg] > 0)
    e = off / safe[..., None]
    d_area, _ = single_beam_excess(ra[:, None], rb, safe)
    dv, d1, d2, dr = single_beam_moments(ra[:, None], rb, safe)
    excess = axial_moments(e, dv, d1, d2, dr)  # (G, B, 4, 4)
    area = 4 * math.pi * ra[vg] ** 2 + np.sum(np.where(present, d_area[vg], 0.0), axis=1)
    moments = ball_moments(ra[vg]) + np.einsum("vb,vbij->vij", present.astype(float), excess[vg])
    if off.shape[1] >= 2 and len(vg):
        oa, om = _overlaps(ra, e, safe, rb, vg, present, grid, turned)
        area -= oa
        moments -= om
    return area, moments


def _overlaps(ra, e, length, rb, vg, present, grid, turned):
    """Overlap ∫ (Σ_b f_b − f_max) dω per variant, for the area integrand and the moment matrix."""
    dirs, w = sphere_quadrature(grid, turned)
    m, nb_max = len(dirs), e.shape[1]
    w1 = w[:, None] * dirs
    w2 = (w[:, None, None] * dirs[:, :, None] * dirs[:, None, :]).reshape(m, 9)
    ball = np.concatenate([np.eye(3).reshape(-1) * 4 * math.pi / 15, np.zeros(3), [4 * math.pi / 3]])

    def integrals(t, fa):  # (…, M) → (…, 14): area, second (9), first (3), volume, in node-radius units
        t3 = t.astype(float) ** 3
        return np.concatenate([(fa @ w)[..., None], (t3 * t * t) @ w2 / 5, (t3 * t) @ w1 / 4,
                               (t3 @ w / 3)[..., None]], axis=-1)

    out = np.zeros((len(vg), 14))
    geos = np.unique(vg)
    per = max(1, CHUNK_RAYS // (nb_max * m))
    for lo in range(0, len(geos), per):
        g = geos[lo:lo + per]
        rows = np.nonzero(np.isin(vg, g))[0]
        local = np.searchsorted(g, vg[rows])
        t, fa = beam_exits(ra[g], e[g], length[g], rb[g], dirs)
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
        unit_ball = np.concatenate([[4 * math.pi], ball])
        out[rows] = total - integrals(tmax, famax) - (nb - 1)[:, None] * unit_ball
    r = ra[vg]
    area = out[:, 0] * r**2
    mom = np.zeros((len(vg), 4, 4))
    mom[:, :3, :3] = out[:, 1:10].reshape(-1, 3, 3) * (r**5)[:, None, None]
    mom[:, :3, 3] = mom[:, 3, :3] = out[:, 10:13] * (r**4)[:, None]
    mom[:, 3, 3] = out[:, 13] * r**3
    return area, mom


def _grid_for(geometries: int, beams: int, grid: int) -> int:
    """The overlap quadrature grid: ``grid`` if given, else GRID_FINE within the ray budget."""
    if grid:
        return int(grid)
    fit = int(math.sqrt(RAY_BUDGET / max(1, 6 * geometries * beams)))
    return int(np.clip(fit, GRID_MIN, GRID_FINE))


def _measure_classes(geo, variants, grid: int):
    """Hub classes: geometry arrays (ra, off, rb) of G geometries and V variants (geometry id,
    present mask). Returns areas, moment matrices, the grid and the relative error estimate."""
    (ra, off, rb), (vg, present) = geo, variants
    n = _grid_for(len(ra), off.shape[1], grid)
    area, mom = hub_moments(ra, off, rb, present, vg, n)
    # error estimate: a sample of multi-beam variants re-measured on grid 2n (turned); the
    # quadrature error is systematic, so the sample's summed difference, relative to its volume
    multi = np.nonzero(present.sum(axis=1) >= 2)[0]
    error = 0.0
    if len(multi):
        pick = multi[np.linspace(0, len(multi) - 1, min(ERROR_SAMPLE, len(multi))).astype(np.int64)]
        a2, m2 = hub_moments(ra, off, rb, present[pick], vg[pick], 2 * n, turned=True)
        rel_v = abs(np.sum(m2[:, 3, 3] - mom[pick, 3, 3])) / np.sum(np.abs(mom[pick, 3, 3]))
        rel_a = abs(np.sum(a2 - area[pick])) / np.sum(np.abs(area[pick]))
        error = float(max(rel_v, rel_a))
    return area, mom, n, error


def _classes(lat: Lattice, reps: np.ndarray, box, grid: int, present=None, hub_rep=None):
    """Measured classes of hubs. ``reps`` (R, 4) representative hubs; without ``present`` each rep is
    one hub with the beams inside ``box``; with it, hubs (H,) map to reps by ``hub_rep`` and carry
    their own kept beams ``present`` (H, B). Returns (class per hub, areas, moments, stats)."""
    ra, off, rb, box_present, f = _hub_geometry(lat, reps, box)
    if present is None:
        present, hub_rep = box_present, np.arange(len(reps))
    key = np.round(np.concatenate([reps[:, 3:], ra[:, None], off.reshape(len(reps), -1), rb], axis=1), 9)
    key[key == 0] = 0.0
    _, geo_first, geo = _unique_rows(key)
    hub_geo = geo[hub_rep]
    _, first, cls = _unique_rows(np.concatenate([hub_geo[:, None], present], axis=1).astype(np.float64))
    g = geo_first  # geometry id → its first representative
    area, mom, n, err = _measure_classes((ra[g], off[g], rb[g]), (hub_geo[first], present[first]), grid)
    stats = {"hubs": int(len(hub_rep)), "hub_shapes": int(len(first)), "hub_geometries": int(len(g)),
             "quadrature_grid": n, "quadrature_rel_error": err}
    return cls.reshape(-1), area, mom, stats


def _unique_rows(a: np.ndarray):
    """np.unique(a, axis=0) with index and inverse, through one byte string per row (faster)."""
    a = np.ascontiguousarray(a)
    rows = a.view(np.dtype((np.void, a.dtype.itemsize * a.shape[1]))).reshape(-1)
    u, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    return u, first, inverse.reshape(-1)


def _frames(lat: Lattice, idx: np.ndarray):
    """Homogeneous matrices (H, 4, 4) of the hubs' node-centred frames and their factors (H,)."""
    m = lat.group_matrices(idx[:, 0], idx[:, 1], idx[:, 2])
    tc = lat.template_centers[idx[:, 3]]
    m[:, :3, 3] += np.einsum("hab,hb->ha", m[:, :3, :3], tc)
    return m, lat.group_factors(idx[:, 0], idx[:, 1], idx[:, 2])


# ----- lattices ------------------------------------------------------------------------------------------
def mass_properties(lat: Lattice, region=None, method: str = "auto", grid: int = 0) -> dict:
    """Integral properties of a clean lattice, of an index ``region`` of it, or of its kept part when
    it carries a filter (``lat.filter``: kept nodes and the beams whose two ends are kept).

    Returns {"area", "volume", "centroid" (3,), "inertia" (3, 3) about the centroid (unit density),
    "second_moment" (3, 3) about the centroid, "closed_form" (bool), "method", "filtered", "hubs",
    "hub_shapes", "hub_geometries", "quadrature_grid", "quadrature_error" (estimated absolute error
    of the volume)}; {"method": "skipped: …"} when too many hub classes would need measuring.
    ``method``: "auto" (closed-form series where hubs are similar; per kept hub for filtered
    lattices), "sum" (every hub added: the reference). ``grid`` fixes the overlap quadrature grid
    (0: GRID_FINE within RAY_BUDGET). Results are cached on the lattice object, keyed by its
    program, filter, region and arguments."""
    lat.validate()
    if method not in ("auto", "sum"):
        raise PleError(f"unknown mass-properties method {method!r} (auto or sum)")
    r = lat.region(region)
    key = (lattice_key(lat), id(lat.filter), str(r), method, int(grid))
    cache = lat.__dict__.setdefault(CACHE_ATTR, {})
    if key in cache:
        return dict(cache[key][0])
    box = (np.array([r.i0, r.j0, r.k0]), np.array([r.i1, r.j1, r.k1]))
    if lat.filter is None:
        out = _unfiltered(lat, box, method, grid)
    else:
        out = _filtered(lat, r, box, method, grid)
    out["filtered"] = lat.filter is not None
    cache.clear()  # one entry per lattice object (the latest question)
    cache[key] = (out, lat.filter)  # the filter is kept alive so that its id stays unique
    return dict(out)


def _unfiltered(lat: Lattice, box, method: str, grid: int) -> dict:
    lo, hi = box
    similar = similar_axes(lat) if method == "auto" else (False, False, False)
    segs = [[(a + x0, b + x0, rep + x0) for a, b, rep in _segments(int(x1 - x0), rch, sim)]
            for x0, x1, rch, sim in zip(lo, hi, reach(lat), similar)]
    n_hubs = len(segs[0]) * len(segs[1]) * len(segs[2]) * len(lat.nodes)
    if n_hubs > MAX_HUBS:
        return {"method": f"skipped: {n_hubs} hub classes to measure (limit {MAX_HUBS})"}
    grids = np.meshgrid(*(np.arange(len(s)) for s in segs), np.arange(len(lat.nodes)), indexing="ij")
    sa, sb, sc, n = (x.reshape(-1) for x in grids)
    seg_ids = np.stack([sa, sb, sc], axis=1)
    reps = np.stack([np.array([g[2] for g in segs[d]])[seg_ids[:, d]] for d in range(3)] + [n], axis=1)
    cls, area, mom, stats = _classes(lat, reps, box, grid)
    frames, f = _frames(lat, reps)
    world = transform(mom[cls], frames, f)  # (H, 4, 4): each representative hub in place
    hub_area = area[cls] * f * f
    # §3.6, §3.7, §6.1.4: a segment of similar hubs is the representative moved by G X^d G⁻¹, d < length
    g = lat.placement.matrix
    g_inv = np.linalg.inv(g)
    flat = world.reshape(len(reps), 16)
    for d, step in enumerate((lat.U, lat.V, lat.W)):
        lengths = np.array([b - a for a, b, _ in segs[d]])[seg_ids[:, d]]
        for length in np.unique(lengths[lengths > 1]):
            rows = lengths == length
            op = series_operator(g @ step.matrix @ g_inv, step.factor, int(length))
            flat[rows] = flat[rows] @ op.T
            hub_area[rows] *= _scalar_series(step.factor**2, int(length))
    total = flat.sum(axis=0).reshape(4, 4)
    axes = "".join(name for name, sim in zip("UVW", similar) if sim)
    label = {"UVW": "closed form O(1) (§3.7)", "VW": "closed form O(ū) (§3.6)",
             "W": "closed form O(ūv̄) (§6.1.4)"}.get(axes, "sum over hubs")
    out = summary(total, float(hub_area.sum()))
    out.update(stats, method=label, closed_form=label != "sum over hubs")
    out["quadrature_error"] = out.pop("quadrature_rel_error") * out["volume"]
    return out


def _scalar_series(q: float, n: int) -> float:
    return float(operator_geometric_sum(np.array([[q]]), n)[0, 0])


def _filtered(lat: Lattice, r, box, method: str, grid: int) -> dict:
    lo, hi = box
    if lat.node_count() > MAX_KEPT_NODES and r.groups * len(lat.nodes) > MAX_KEPT_NODES:
        return {"method": f"skipped: {r.groups * len(lat.nodes)} nodes to filter (limit {MAX_KEPT_NODES})"}
    ev = lat.evaluate(r)
    kept = ev.node_index
    if not len(kept):
        out = summary(np.zeros((4, 4)), 0.0)
        out.update(method="sum over kept hubs", closed_form=False, hubs=0, hub_shapes=0, hub_geometries=0,
                   quadrature_grid=None, quadrature_error=0.0)
        return out
    nn = len(lat.nodes)
    shape = tuple(hi - lo)
    alive = np.zeros(shape + (nn,), bool)
    alive[tuple((kept[:, :3] - lo).T) + (kept[:, 3],)] = True
    # each kept hub's kept half-beams: partner inside the box and kept
    offs, partner, valid = incidence_table(lat)
    pidx = kept[:, None, :3] + offs[kept[:, 3]]
    inside = np.all((pidx >= lo) & (pidx < hi), axis=2) & valid[kept[:, 3]]
    rel = np.where(inside[..., None], pidx - lo, 0)
    present = inside & alive[rel[..., 0], rel[..., 1], rel[..., 2], partner[kept[:, 3]]]
    # representatives: hubs of the interior of similar directions share their geometry (§3.6)
    similar = similar_axes(lat) if method == "auto" else (False, False, False)
    rch = reach(lat)
    rep = kept.copy()
    for d in range(3):
        if similar[d] and hi[d] - lo[d] > 2 * rch[d] + 1:
            interior = (kept[:, d] >= lo[d] + rch[d]) & (kept[:, d] < hi[d] - rch[d])
            rep[interior, d] = lo[d] + rch[d]
    reps, hub_rep = np.unique(rep, axis=0, return_inverse=True)
    if len(reps) > MAX_HUBS:
        return {"method": f"skipped: {len(reps)} hub geometries to measure (limit {MAX_HUBS})"}
    cls, area, mom, stats = _classes(lat, reps, box, grid, present=present, hub_rep=hub_rep.reshape(-1))
    total, total_area = np.zeros((4, 4)), 0.0
    for s in range(0, len(kept), HUB_CHUNK):
        part = slice(s, s + HUB_CHUNK)
        frames, f = _frames(lat, kept[part])
        total += transform(mom[cls[part]], frames, f).sum(axis=0)
        total_area += float(np.sum(area[cls[part]] * f * f))
    out = summary(total, total_area)
    out.update(stats, method="sum over kept hubs", closed_form=False)
    out["quadrature_error"] = out.pop("quadrature_rel_error") * out["volume"]
    return out
