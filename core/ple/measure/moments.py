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
f = (R³/3, R⁴/4 ω, R⁵/5 ω ωᵀ) on a cubed-sphere grid — ``integrals.hub_moments``, the one hub
routine, whose area and volume are also ``integrals.lattice_measures``'. Hubs that are similar
copies (after normalization by their group similarity) share one measurement.

Unfiltered lattices and regions: the interior segments of the similar directions (as in
``integrals.lattice_measures``) are summed by operator series; filtered lattices (``lat.filter``):
every kept hub is added, with the beams whose two ends are kept, hub shapes shared by
(geometry, kept beams). The overlap quadrature is turned by random rotations per hub geometry
and refined until the estimated error of the lattice's sums is small (``integrals.hub_moments``).
"""

from __future__ import annotations

import numpy as np

from ..algebra.series import operator_geometric_sum
from ..errors import PleError, echo
from ..model.lattice import Lattice
from ..queries.overlaps import reach, similar_axes
from ..queries.plans import lattice_key
from .integrals import MAX_HUBS, hub_geometry, hub_moments, incidence_table, row_segments, unique_rows

HUB_CHUNK = 1 << 16  # kept hubs per block of the per-hub sums
MAX_KEPT_NODES = 20_000_000  # filtered lattices are evaluated in full; beyond this, no moments
CACHE_ATTR = "_mass_properties"


# ----- moment matrices of simple solids --------------------------------------------------------------
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
def _classes(lat: Lattice, reps: np.ndarray, box, grid: int, weights, present=None, hub_rep=None):
    """Measured classes of hubs. ``reps`` (R, 4) representative hubs; without ``present`` each rep is
    one hub with the beams inside ``box``; with it, hubs (H,) map to reps by ``hub_rep`` and carry
    their own kept beams ``present`` (H, B). ``weights`` (H, 2): each hub's area and volume weight in
    the lattice's sum (for the quadrature's error control). Returns (class per hub, areas, moments,
    stats)."""
    ra, off, rb, box_present, f = hub_geometry(lat, reps, box)
    if present is None:
        present, hub_rep = box_present, np.arange(len(reps))
    key = np.round(np.concatenate([reps[:, 3:], ra[:, None], off.reshape(len(reps), -1), rb], axis=1), 9)
    key[key == 0] = 0.0
    _, geo_first, geo = unique_rows(key)
    hub_geo = geo[hub_rep]
    _, first, cls = unique_rows(np.concatenate([hub_geo[:, None], present], axis=1).astype(np.float64))
    class_weights = np.zeros((len(first), 2))
    np.add.at(class_weights, cls, weights)
    g = geo_first  # geometry id → its first representative
    area, mom, quad = hub_moments(ra[g], off[g], rb[g], present[first], hub_geo[first], grid, class_weights)
    stats = {"hubs": int(len(hub_rep)), "hub_shapes": int(len(first)), "hub_geometries": int(len(g)), **quad}
    return cls.reshape(-1), area, mom, stats


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
    "hub_shapes", "hub_geometries", "quadrature_grid", "quadrature_rotations", "quadrature_error"
    (estimated absolute error, 3 σ, of the volume)}; {"method": "skipped: …"} when too many hub
    classes would need measuring.
    ``method``: "auto" (closed-form series where hubs are similar; per kept hub for filtered
    lattices), "sum" (every hub added: the reference). ``grid`` fixes the overlap quadrature grid
    (0: refined until its error is small, ``integrals.hub_moments``). Results are cached on the
    lattice object, keyed by its program, filter, region and arguments."""
    lat.validate()
    if method not in ("auto", "sum"):
        raise PleError(f"unknown mass-properties method {echo(method)} (auto or sum)")
    r = lat.region(region)
    key = (lattice_key(lat), id(lat.filter), str(r), method, int(grid))
    cache = lat.__dict__.setdefault(CACHE_ATTR, {})
    if key in cache:
        return dict(cache[key][0])
    box = (np.array([r.i0, r.j0, r.k0]), np.array([r.i1, r.j1, r.k1]))
    if lat.radius_field is not None:  # graded radii: no two hubs alike, every hub measured
        method = "sum"
    if lat.filter is None and lat.radius_field is None:
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
    segs = [[(a + x0, b + x0, rep + x0) for a, b, rep in row_segments(int(x1 - x0), rch, sim)]
            for x0, x1, rch, sim in zip(lo, hi, reach(lat), similar)]
    n_hubs = len(segs[0]) * len(segs[1]) * len(segs[2]) * len(lat.nodes)
    if n_hubs > MAX_HUBS:
        return {"method": f"skipped: {n_hubs} hub classes to measure (limit {MAX_HUBS})"}
    grids = np.meshgrid(*(np.arange(len(s)) for s in segs), np.arange(len(lat.nodes)), indexing="ij")
    sa, sb, sc, n = (x.reshape(-1) for x in grids)
    seg_ids = np.stack([sa, sb, sc], axis=1)
    reps = np.stack([np.array([g[2] for g in segs[d]])[seg_ids[:, d]] for d in range(3)] + [n], axis=1)
    frames, f = _frames(lat, reps)
    series = np.ones((len(reps), 2))  # how many times (× f², × f³) each representative counts (§3.6)
    for d, step in enumerate((lat.U, lat.V, lat.W)):
        lengths = np.array([b - a for a, b, _ in segs[d]])[seg_ids[:, d]]
        for length in np.unique(lengths[lengths > 1]):
            series[lengths == length] *= [_scalar_series(step.factor**p, int(length)) for p in (2, 3)]
    cls, area, mom, stats = _classes(lat, reps, box, grid, series * np.stack([f * f, f**3], axis=1))
    world = transform(mom[cls], frames, f)  # (H, 4, 4): each representative hub in place
    hub_area = area[cls] * f * f * series[:, 0]
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
    f = lat.group_factors(kept[:, 0], kept[:, 1], kept[:, 2])
    cls, area, mom, stats = _classes(lat, reps, box, grid, np.stack([f * f, f**3], axis=1), present=present,
                                     hub_rep=hub_rep.reshape(-1))
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
