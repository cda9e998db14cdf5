"""CHoCC: the convex hull of n disjoint cospherical circles (CHoCC paper, 001_ §3–4).

All constructions work on the unit sphere centred at the origin; a circle is given by the
unit normal ``N`` of its plane (pointing out of the sphere, towards its cap) and the
half-angle ``alpha`` of its cone K(C) (circle radius ``sin alpha``, plane ``x·N = cos alpha``).
A circle with ``alpha == 0`` is a *point circle* (the infinitesimal circle of §6).

Boundary (§3): n disks, t = 2n − 4 triangles (vertices on three different circles),
3n − 6 corridors (elliptic-cone patches bounded by two triangle edges and two arcs), and
6n − 12 vertices. Triangles are found by plane rolling (§3.3) with the closed-form
Apollonius construction on the sphere (§3.4, Appendix A); corridors are sampled as strips
of cone generators through their apex (§4, Eq. 3–5).

Orientation convention: triangles are counter-clockwise seen from outside; the vertices
on each circle form a *ring*, listed clockwise about the circle's normal N (the order in
which the corridors traverse the circle's arcs), so a disk face is the reversed ring.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..algebra.vectors import cross, perpendicular_frames, unit_rows
from ..errors import PleError

# Tie-breaking perturbation of the cone half-angles during plane rolling: four circles
# tangent to one plane (common in symmetric lattices) make the rolling choice ambiguous;
# a deterministic 1e-6 perturbation makes it a strict choice. Geometry uses exact angles.
TIE_PERTURBATION = 1e-6
SUPPORT_TOL = 1e-10  # a supporting plane may cut a circle's cone by at most this (cosine units)
ROLL_SLACK = 1e-9  # turns down to -1e-9 rad count as rolling forward (coplanar neighbours)
NEAR_COPLANAR = 1e-3  # |N1·(N2×N3)| below this: Appendix A divides by ~0, use Eq. A.3's case
DEGENERATE_ARC = 1e-12  # a corridor whose arcs and ends are this short is a bare edge


def _solve_homogeneous_quadratic(q: np.ndarray) -> np.ndarray:
    """Unit (c, s) with [c s] q [c s]ᵀ = 0 for symmetric 2x2 ``q`` (..., 2, 2): (..., 2, 2)
    (two solutions, NaN where q is definite). Eigen form avoids Appendix A's division by
    B·B − 1 (which vanishes for alpha = 90°)."""
    lam, vec = np.linalg.eigh(q)
    lo, hi = lam[..., 0], lam[..., 1]
    ok = (lo <= 0) & (hi >= 0)
    a = np.sqrt(np.clip(hi, 0, None))[..., None] * vec[..., :, 0]
    b = np.sqrt(np.clip(-lo, 0, None))[..., None] * vec[..., :, 1]
    sol = np.stack([a + b, a - b], axis=-2)
    sol = unit_rows(sol)
    sol[~ok] = np.nan
    return sol


def appendix_a(n: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Appendix A (001_): planes tangent to three circles, N = cos(a) A − sin(a) B.

    n (..., 3, 3) circle normals, alpha (..., 3) half-angles. Returns the normals
    (..., 2, 3) and half-angles (..., 2) of the two circles C with
    cos(alpha_C + alpha_i) = N_C · N_i (the caps outside K(C)), sin(alpha_C) > 0.
    Undefined (inf/NaN) when the normals are coplanar; see ``apollonius_planes``."""
    n1, n2, n3 = n[..., 0, :], n[..., 1, :], n[..., 2, :]
    c23, c31, c12 = cross(n2, n3), cross(n3, n1), cross(n1, n2)
    det = np.einsum("...i,...i->...", n1, c23)[..., None]
    ca, sa = np.cos(alpha), np.sin(alpha)
    a = (ca[..., 0:1] * c23 + ca[..., 1:2] * c31 + ca[..., 2:3] * c12) / det
    b = (sa[..., 0:1] * c23 + sa[..., 1:2] * c31 + sa[..., 2:3] * c12) / det
    aa, bb, ab = (np.einsum("...i,...i->...", x, y) for x, y in ((a, a), (b, b), (a, b)))
    # (c, s) on the unit circle with |c A − s B|² = 1: c²(A·A−1) − 2cs A·B + s²(B·B−1) = 0
    q = np.stack([np.stack([aa - 1, -ab], -1), np.stack([-ab, bb - 1], -1)], -2)
    cs = _solve_homogeneous_quadratic(q)  # (..., 2, 2)
    cs = cs * np.where(cs[..., 1:2] < 0, -1.0, 1.0)  # sin(alpha_C) > 0
    normals = cs[..., 0:1] * a[..., None, :] - cs[..., 1:2] * b[..., None, :]
    return normals, np.arctan2(cs[..., 1], cs[..., 0])


def _null_space_planes(n: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Same solutions via the null space of the linear rows (N_i, −cos a_i, sin a_i) acting
    on (N, cos a, sin a): the coplanar-normals case of Eq. A.3, valid for any normals."""
    rows = np.concatenate([n, -np.cos(alpha)[..., None], np.sin(alpha)[..., None]], axis=-1)  # (..., 3, 5)
    finite = np.isfinite(rows).all(axis=(-2, -1))
    # LAPACK's SVD does not converge on NaN: such triples get NaN planes (no candidate)
    vt = np.full(rows.shape[:-2] + (5, 5), np.nan)
    vt[finite] = np.linalg.svd(rows[finite])[2]
    e = vt[..., 3:, :]  # (..., 2, 5) null-space basis
    d = np.array([1.0, 1.0, 1.0, -1.0, -1.0])
    q = np.einsum("...ai,i,...bi->...ab", e, d, e)  # |N|² − cos² − sin² = 0
    xy = _solve_homogeneous_quadratic(q)  # (..., 2, 2)
    p = np.einsum("...sa,...ai->...si", xy, e)  # (..., 2, 5)
    scale = np.linalg.norm(p[..., 3:], axis=-1, keepdims=True)
    p = p / np.where(scale > 0, scale, np.nan)
    p = p * np.where(p[..., 4:5] < 0, -1.0, 1.0)
    return unit_rows(p[..., :3]), np.arctan2(p[..., 4], p[..., 3])


def apollonius_planes(n: np.ndarray, alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two supporting-plane candidates of three cospherical circles (§3.4, Eq. 1).

    Appendix A's closed form where the normals are well spread; the coplanar special case
    (Eq. A.3) — three cap centres on one great circle, frequent in lattices — by the null
    space of the same linear system. Shapes as ``appendix_a``."""
    n = np.asarray(n, float)
    alpha = np.asarray(alpha, float)
    det = np.abs(np.einsum("...i,...i->...", n[..., 0, :], cross(n[..., 1, :], n[..., 2, :])))
    with np.errstate(divide="ignore", invalid="ignore"):
        normals, angles = appendix_a(n, alpha)
    flat = det < NEAR_COPLANAR
    if np.any(flat):
        fn, fa = _null_space_planes(n[flat], alpha[flat])
        normals[flat], angles[flat] = fn, fa
    return normals, angles


def contact_points(n_plane: np.ndarray, a_plane: np.ndarray, n_circ: np.ndarray) -> np.ndarray:
    """Tangency points of circle (n_plane, a_plane) with circles of normals n_circ on the unit
    sphere (Eq. 2, written as the point at angle a_plane from n_plane towards N_i, which stays
    well defined when sin(alpha + alpha_i) → 0). Broadcasts; returns (..., 3)."""
    u = unit_rows(n_circ - np.einsum("...i,...i->...", n_circ, n_plane)[..., None] * n_plane)
    return np.cos(a_plane)[..., None] * n_plane + np.sin(a_plane)[..., None] * u


def _support_violation(n_plane, a_plane, normals, alphas) -> np.ndarray:
    """max over circles of how far each cuts the plane's outer side (≤ 0: supporting)."""
    lim = np.minimum(a_plane[..., None] + alphas, np.pi)
    return (np.einsum("...i,mi->...m", n_plane, normals) - np.cos(lim)).max(axis=-1)


def _candidates(normals, alphas, triples):
    """Both candidate planes of each (a, b, c) triple, with the CCW orientation of a, b, c
    about each plane's normal: normals (m, 2, 3), angles (m, 2), contact (m, 2, 3, 3), ccw (m, 2)."""
    pn, pa = apollonius_planes(normals[triples], alphas[triples])
    pts = contact_points(pn[:, :, None, :], pa[:, :, None], normals[triples][:, None, :, :])
    ccw = np.einsum("msi,msi->ms", cross(pts[:, :, 1] - pts[:, :, 0], pts[:, :, 2] - pts[:, :, 0]), pn)
    return pn, pa, pts, ccw


def roll_planes(normals: np.ndarray, alphas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (2n−4, 3) of the CHoCC of n ≥ 3 circles by plane rolling (§3.3), CCW, and
    their adjacency ``twin`` (2n−4, 3, 2): the (triangle, corner) across each edge
    corner → corner+1.

    Start from the plane of circle 0 and roll it onto the pair (j, k) with the smallest
    rotation; then pop exposed borders (a, b), roll the adjacent triangle's plane about them
    onto the circle l of least rotation. Borders are matched by the triangle they lead to
    (an oriented triple names one plane), not by the circle pair alone: two circles can share
    two corridors when a small circle sits in the gap between them."""
    n = len(normals)
    alphas = tie_broken(normals, alphas)
    others = np.arange(1, n)
    jj, kk = np.triu_indices(len(others), 1)
    triples = np.stack([np.zeros(len(jj), int), others[jj], others[kk]], axis=1)
    pn, pa, pts, ccw = _candidates(normals, alphas, triples)
    viol = _support_violation(pn, pa, normals, alphas)
    score = np.where((viol <= SUPPORT_TOL) & np.isfinite(pa), pn @ normals[0], -np.inf)
    best = np.unravel_index(np.argmax(score), score.shape)
    if not np.isfinite(score[best]):
        raise PleError("CHoCC: no supporting plane found (caps overlap?)")
    t0 = triples[best[0]]
    tri0 = (int(t0[0]), int(t0[1]), int(t0[2])) if ccw[best] > 0 else (int(t0[0]), int(t0[2]), int(t0[1]))
    triangles = [tri0]
    planes = [pn[best]]
    p0 = pts[best]
    points = [p0 if ccw[best] > 0 else p0[[0, 2, 1]]]
    index = {_cyclic_key(tri0): 0}
    twin: dict[tuple[int, int], tuple[int, int]] = {}
    stack = [(0, 2), (0, 1), (0, 0)]
    limit = 2 * n - 4
    while stack:
        he = stack.pop()
        if he in twin:
            continue
        ti, k = he
        a, b = triangles[ti][k], triangles[ti][(k + 1) % 3]
        ls = np.array([x for x in range(n) if x != a and x != b])
        tr = np.stack([np.full(len(ls), b), np.full(len(ls), a), ls], axis=1)
        pn, pa, pts, ccw = _candidates(normals, alphas, tr)
        viol = _support_violation(pn, pa, normals, alphas)
        ok = (ccw > 0) & (viol <= SUPPORT_TOL) & np.isfinite(pa)
        # roll over the edge: the normal turns from n_T towards o = e × n_T (away from the
        # triangle's interior); take the least positive turn. Measuring the signed turn (not
        # the unsigned angle between normals) separates the two ways around a symmetric hinge.
        nt = planes[ti]
        e = points[ti][(k + 1) % 3] - points[ti][k]
        o = cross(e, nt)
        o /= max(np.linalg.norm(o), 1e-300)
        turn = (np.arctan2(pn @ o, pn @ nt) + ROLL_SLACK) % (2 * np.pi)
        score = np.where(ok, -turn, -np.inf)
        best = np.unravel_index(np.argmax(score), score.shape)
        if not np.isfinite(score[best]):
            raise PleError("CHoCC: plane rolling found no next triangle (degenerate circles?)")
        new = (b, a, int(ls[best[0]]))
        key = _cyclic_key(new)
        if key not in index:
            if len(triangles) == limit:
                raise PleError(f"CHoCC: plane rolling produced more than 2n-4 = {limit} triangles")
            index[key] = len(triangles)
            triangles.append(new)
            planes.append(pn[best])
            points.append(pts[best])
            stack += [(index[key], 2), (index[key], 1)]
        t2 = index[key]
        k2 = next(c for c in range(3) if triangles[t2][c] == b and triangles[t2][(c + 1) % 3] == a)
        if (t2, k2) in twin:
            raise PleError("CHoCC: plane rolling reached an edge twice (inconsistent rolling)")
        twin[he] = (t2, k2)
        twin[(t2, k2)] = he
    if len(triangles) != limit or len(twin) != 3 * limit:
        raise PleError(f"CHoCC: plane rolling closed with {len(triangles)} triangles, expected {limit}")
    tw = np.zeros((limit, 3, 2), np.int64)
    for (ti, k), (t2, k2) in twin.items():
        tw[ti, k] = (t2, k2)
    return np.array(triangles, dtype=np.int64), tw


def tie_broken(normals: np.ndarray, alphas: np.ndarray) -> np.ndarray:
    """The half-angles (..., n) plane rolling works with: ``alphas`` perturbed by at most
    TIE_PERTURBATION so that no four circles touch one plane (normals (..., n, 3))."""
    n = normals.shape[-2]
    gap = (np.arccos(np.clip(np.einsum("...ai,...bi->...ab", normals, normals), -1, 1))
           - (alphas[..., :, None] + alphas[..., None, :]))
    gap[..., np.arange(n), np.arange(n)] = np.inf
    # the perturbation must stay well below the narrowest gap between caps (near-tangent circles)
    # pseudo-random, not affine in the index: an affine perturbation keeps symmetric ties
    wiggle = 0.5 + 0.5 * ((np.sin(np.arange(1, n + 1) * 12.9898) * 43758.5453) % 1.0)
    return alphas + np.minimum(TIE_PERTURBATION, 0.01 * gap.min(axis=(-2, -1)))[..., None] * wiggle


def _cyclic_key(tri) -> tuple[int, int, int]:
    r = min(range(3), key=lambda c: tri[c])
    return (tri[r], tri[(r + 1) % 3], tri[(r + 2) % 3])


@dataclass
class Chocc:
    """Boundary of the CHoCC of circles (normals (n, 3), alphas (n,)) on the unit sphere.

    triangles (t, 3) circle ids (CCW from outside); plane_normals (t, 3), plane_alphas (t,);
    points (t, 3, 3) the triangle vertices (vertex id = 3 * triangle + corner);
    corridors (3n−6, 4): circle i, circle j, triangle T1 (holding edge i→j), T2 (holding j→i);
    rings: per circle, the vertex ids on it clockwise about N with, between consecutive ones,
    the corridor whose arc joins them (ring_corridors).
    """

    normals: np.ndarray
    alphas: np.ndarray
    triangles: np.ndarray
    plane_normals: np.ndarray
    plane_alphas: np.ndarray
    points: np.ndarray
    corridors: np.ndarray
    twin: np.ndarray = None
    rings: list = field(default_factory=list)
    ring_corridors: list = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.normals)

    def counts(self) -> dict:
        """Face/vertex counts of §3 (disks, triangles, corridors, vertices, faces)."""
        t = len(self.triangles)
        return {"disks": self.n, "triangles": t, "corridors": len(self.corridors), "vertices": 3 * t,
                "faces": self.n + t + len(self.corridors)}

    def apex(self, corridor: int) -> np.ndarray:
        """Homogeneous apex (x, y, z, w) of corridor's elliptic cone (Eq. 3–5), w = 0 when the
        cone is a cylinder (equal circles: the apex is at infinity)."""
        return corridor_apexes(self.normals, self.alphas, self.corridors[corridor:corridor + 1, :2])[0]


def corridor_apexes(normals: np.ndarray, alphas: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Homogeneous apex (m, 4) of the cone through circles pairs[:, 0], pairs[:, 1] (§4)."""
    return cone_apex(normals[pairs[:, 0]], normals[pairs[:, 1]], alphas[pairs[:, 0]], alphas[pairs[:, 1]])


def cone_apex(n1: np.ndarray, n2: np.ndarray, a1: np.ndarray, a2: np.ndarray) -> np.ndarray:
    """Homogeneous apex (..., 4) of the cone through circles (n1, a1) and (n2, a2) (§4),
    broadcasting over leading axes (normals (..., 3), half-angles (...)).

    In the plane M through O, O1, O2 (Eq. 3) the circles meet M at angles ±a1 (C1) and
    θ ± a2 (C2); the corridor's generators in M are the sides of the cyclic quad joining
    them (Eq. 4–5), and their 2D homogeneous intersection stays finite (w = 0) for equal circles."""
    e1 = n1
    e2 = unit_rows(n2 - np.einsum("...i,...i->...", n2, n1)[..., None] * n1)
    th = np.arctan2(np.einsum("...i,...i->...", n2, e2), np.einsum("...i,...i->...", n2, n1))

    def h(phi):
        return np.stack([np.cos(phi), np.sin(phi), np.ones_like(phi)], axis=-1)

    line1 = cross(h(a1), h(th - a2))
    line2 = cross(h(-a1), h(th + a2))
    f = cross(line1, line2)
    out = np.concatenate([f[..., :1] * e1 + f[..., 1:2] * e2, f[..., 2:3]], axis=-1)
    norm = np.linalg.norm(out, axis=-1, keepdims=True)
    # two point circles: both generator lines coincide (the corridor is one segment)
    return np.where(norm > 0, out / np.where(norm > 0, norm, 1.0), np.array([0, 0, 0, 1.0]))


def map_generators(points: np.ndarray, apex: np.ndarray, n2: np.ndarray, a2: np.ndarray) -> np.ndarray:
    """Other ends, on the plane x·n2 = cos(a2), of the cone generators through ``points``
    (m, k, 3) and the homogeneous ``apex`` (m, 4) (§4: A' = L(F, A) ∩ plane of C_j)."""
    return generator_ends(points, apex[:, None], n2[:, None], np.asarray(a2)[:, None])


def generator_ends(points: np.ndarray, apex: np.ndarray, n2: np.ndarray, a2: np.ndarray) -> np.ndarray:
    """``map_generators`` elementwise: points (..., 3), apex (..., 4), n2 (..., 3), a2 (...)."""
    d = apex[..., :3] - apex[..., 3:] * points
    t = np.cos(a2) - np.einsum("...i,...i->...", points, n2)
    den = np.einsum("...i,...i->...", d, n2)
    t = t / np.where(np.abs(den) > 1e-300, den, 1e-300)
    return points + t[..., None] * d


def circle_points(n: np.ndarray, alpha: np.ndarray, e1: np.ndarray, e2: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Points (..., 3) at angle ``theta`` (...) on circles (n (..., 3), alpha (...)) of the unit
    sphere, angles measured in the frame (e1, e2) of n; broadcasts."""
    ring = np.cos(theta)[..., None] * e1 + np.sin(theta)[..., None] * e2
    return np.cos(alpha)[..., None] * n + np.sin(alpha)[..., None] * ring


def corridor_ends(na, nb, aa, ab, fa, fb, th_a0, da, th_b0, db, s, apexes) -> tuple[np.ndarray, np.ndarray]:
    """Both ends (..., 3) of the generator at arc parameter ``s`` (0..1 from T1 to T2) of the
    corridor between circles a (na, aa) and b (nb, ab), broadcasting over leading axes (§4).

    The larger circle is swept uniformly in angle (clockwise on a from th_a0 by da,
    counter-clockwise on b from th_b0 by db, in the frames fa = (e1, e2) of a and fb of b);
    the other end of each generator follows through the cone's apex (``apexes``: the
    homogeneous apexes (..., 4) of the cones a -> b and b -> a, ``cone_apex``)."""
    big = (aa >= ab)[..., None]
    pa = circle_points(na, aa, fa[0], fa[1], th_a0 - s * da)
    pb = circle_points(nb, ab, fb[0], fb[1], th_b0 + s * db)
    return (np.where(big, pa, generator_ends(pb, apexes[1], na, aa)),
            np.where(big, generator_ends(pa, apexes[0], nb, ab), pb))


def _topology_from_hint(normals, alphas, tris):
    """Adopt a known triangle set (e.g. the neighbouring hub's) when it is still the hull:
    every triangle's plane supports all circles with the rolling orientation and every
    directed edge has exactly one reverse. Returns (triangles, twin) or None."""
    tris = np.asarray(tris, np.int64)
    n = len(normals)
    if tris.ndim != 2 or len(tris) != 2 * n - 4 or tris.max() >= n:
        return None
    pn, pa = apollonius_planes(normals[tris], alphas[tris])
    pts = contact_points(pn[:, :, None, :], pa[:, :, None], normals[tris][:, None, :, :])
    ccw = np.einsum("tsi,tsi->ts", cross(pts[:, :, 1] - pts[:, :, 0], pts[:, :, 2] - pts[:, :, 0]), pn)
    lim = np.minimum(pa[..., None] + alphas, np.pi)
    viol = np.einsum("tsi,mi->tsm", pn, normals) - np.cos(lim)  # (t, 2, n)
    own = np.zeros((len(tris), n), bool)
    own[np.arange(len(tris))[:, None], tris] = True
    viol[np.broadcast_to(own[:, None, :], viol.shape)] = -np.inf
    ok = (ccw > 1e-12) & (viol.max(axis=-1) <= -1e-9)  # strict: ties go to plane rolling
    if not np.all(ok.sum(axis=1) == 1):
        return None
    e = np.stack([tris, np.roll(tris, -1, axis=1)], axis=-1).reshape(-1, 2)
    key = e[:, 0] * n + e[:, 1]
    rev = e[:, 1] * n + e[:, 0]
    order = np.argsort(key)
    if np.any(np.diff(key[order]) == 0):
        return None  # a repeated directed edge: two corridors between one pair, roll instead
    pos = np.searchsorted(key[order], rev)
    if np.any(pos >= len(key)) or np.any(key[order][np.minimum(pos, len(key) - 1)] != rev):
        return None
    other = order[pos]
    twin = np.stack([other // 3, other % 3], axis=1).reshape(-1, 3, 2)
    return tris, twin


def chocc(normals, alphas, hint=None) -> Chocc:
    """The CHoCC of n ≥ 3 disjoint cospherical circles on the unit sphere (§3).

    ``hint``: triangles of a similar configuration (a neighbouring hub); adopted after an
    exact validity check, which skips plane rolling for smoothly varying steady lattices.

    The cases n = 1 (a disk) and n = 2 (the hull of two circles: a single corridor band,
    no triangles) have no triangle vertices; callers add point circles (see ``ple.achocc``)."""
    normals = unit_rows(np.asarray(normals, float).reshape(-1, 3))
    alphas = np.asarray(alphas, float).reshape(-1)
    n = len(normals)
    if n < 3:
        raise PleError(f"CHoCC needs at least 3 circles for triangles, got {n} (cases n=1, 2 have none)")
    if not (np.isfinite(normals).all() and np.isfinite(alphas).all()):
        raise PleError("CHoCC: a circle's normal or half-angle is not a finite number")
    if np.any(alphas < 0) or np.any(alphas >= np.pi / 2):
        raise PleError("CHoCC: circle half-angles must lie in [0, pi/2)")
    gap = np.arccos(np.clip(normals @ normals.T, -1, 1)) - (alphas[:, None] + alphas[None, :])
    np.fill_diagonal(gap, np.inf)
    if gap.min() <= 0:
        i, j = np.unravel_index(np.argmin(gap), gap.shape)
        raise PleError(f"CHoCC: caps {i} and {j} overlap or touch")
    known = _topology_from_hint(normals, alphas, hint) if hint is not None else None
    if known is None and hint is not None:  # ties: the hint may still be the hull plane rolling finds
        known = _topology_from_hint(normals, tie_broken(normals, alphas), hint)
    tris, twin = known if known is not None else roll_planes(normals, alphas)
    pn, pa = apollonius_planes(normals[tris], alphas[tris])
    pts = contact_points(pn[:, :, None, :], pa[:, :, None], normals[tris][:, None, :, :])
    ccw = np.einsum("tsi,tsi->ts", cross(pts[:, :, 1] - pts[:, :, 0], pts[:, :, 2] - pts[:, :, 0]), pn)
    viol = _support_violation(pn, pa, normals, alphas)
    # of the two candidates, the supporting one with the rolling orientation (ties: larger ccw)
    key = np.where(viol <= 1e-8, 1.0, 0.0) * 10 + np.sign(np.round(ccw, 14))
    pick = np.argmax(key, axis=1)
    r = np.arange(len(tris))
    c = Chocc(normals, alphas, tris, pn[r, pick], pa[r, pick], pts[r, pick], np.zeros((0, 4), np.int64), twin)
    _connect(c)
    return c


def _connect(c: Chocc) -> None:
    """Corridors (one per pair of twin edges) and the rings of vertices per circle."""
    t = len(c.triangles)
    cors = []
    cor_of = np.zeros((t, 3), np.int64)
    for ti in range(t):
        for k in range(3):
            t2, k2 = c.twin[ti, k]
            if (ti, k) < (int(t2), int(k2)):
                cor_of[ti, k] = cor_of[t2, k2] = len(cors)
                cors.append((c.triangles[ti, k], c.triangles[ti, (k + 1) % 3], ti, t2))
    c.corridors = np.array(cors, dtype=np.int64).reshape(-1, 4)
    rings, ring_cors = [], []
    for i in range(c.n):
        ti, k = np.argwhere(c.triangles == i)[0]
        start = (int(ti), int(k))
        ring, rc = [], []
        while True:
            ring.append(3 * ti + k)
            rc.append(cor_of[ti, k])  # edge i -> j of ti; its twin holds j -> i
            t2, k2 = c.twin[ti, k]
            ti, k = int(t2), (int(k2) + 1) % 3
            if (ti, k) == start:
                break
            if len(ring) > 3 * t:
                raise PleError("CHoCC: ring walk does not close")
        rings.append(np.array(ring, dtype=np.int64))
        ring_cors.append(np.array(rc, dtype=np.int64))
    c.rings, c.ring_corridors = rings, ring_cors


@dataclass
class ChoccMesh:
    """A triangulated CHoCC without its disks: vertices (V, 3) on the unit sphere,
    faces (F, 3) outward, rings (per circle, vertex ids clockwise about N, closed loop),
    vertex_circle (V,) the circle each vertex lies on (all of them do)."""

    vertices: np.ndarray
    faces: np.ndarray
    rings: list
    vertex_circle: np.ndarray
    # where each face lies on the hull: its corridor (-1: a planar CHoCC triangle) and the
    # corridor coordinates (s along the arcs, t from circle a to b) of its corners; with
    # ``corridor_point`` they place refinement points on the curved corridor, not on its chord
    face_corridor: np.ndarray | None = None
    face_params: np.ndarray | None = None
    corridors: list | None = None

    def corridor_point(self, cor: np.ndarray, s: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Points (k, 3) of corridors ``cor`` (k,) at coordinates (s, t): on the generator from
        circle a (t = 0) to circle b (t = 1) at arc parameter s (0..1 from triangle T1 to T2)."""
        out = np.zeros((len(cor), 3))
        for ci in np.unique(cor):
            sel = np.flatnonzero(cor == ci)
            out[sel] = self.corridors[ci](s[sel], t[sel])
        return out

    def disk_faces(self, circles=None) -> np.ndarray:
        """Fan triangulations (outward) of the disks bounded by the rings of ``circles``."""
        out = []
        for i in range(len(self.rings)) if circles is None else circles:
            q = self.rings[i][::-1]
            if len(q) >= 3:
                out.append(np.stack([np.full(len(q) - 2, q[0]), q[1:-1], q[2:]], axis=1))
        return np.concatenate(out) if out else np.zeros((0, 3), np.int64)


def corridor_mesh(c: Chocc, arc_segments) -> ChoccMesh:
    """Tessellate the corridors of ``c`` as strips of cone generators (§4).

    ``arc_segments(delta)`` gives the number of strip quads for an arc of angle delta
    (CNT: 1 per corridor, one planar quad). The larger circle of each corridor is sampled
    uniformly in angle, the other through the apex, so every strip edge is a generator.
    Point circles (alpha = 0) keep a single vertex."""
    n, t = c.n, len(c.triangles)
    e1, e2 = perpendicular_frames(c.normals)
    verts = [c.points.reshape(-1, 3)]
    vcircle = [c.triangles.reshape(-1)]
    nv = 3 * t
    faces = [np.arange(3 * t).reshape(t, 3)]
    per_circle_samples: dict[tuple[int, int], np.ndarray] = {}
    merge: list[tuple[int, int]] = []
    face_cor = [np.full(t, -1, np.int64)]
    face_par = [np.zeros((t, 3, 2))]
    cor_fns: list = [None] * len(c.corridors)
    point = c.alphas == 0.0
    pairs = c.corridors[:, :2]
    apexes = (cone_apex(c.normals[pairs[:, 0]], c.normals[pairs[:, 1]], c.alphas[pairs[:, 0]], c.alphas[pairs[:, 1]]),
              cone_apex(c.normals[pairs[:, 1]], c.normals[pairs[:, 0]], c.alphas[pairs[:, 1]], c.alphas[pairs[:, 0]]))

    def ang(i, p):
        return np.arctan2(p @ e2[i], p @ e1[i])

    def cw_delta(i, p0, p1):
        d = (ang(i, p0) - ang(i, p1)) % (2 * np.pi)
        return 0.0 if d > 2 * np.pi - 1e-9 or point[i] else d

    for ci, (a, b, t1, t2) in enumerate(c.corridors):
        ka1, ka2 = _corner(c, t1, a), _corner(c, t2, a)
        kb1, kb2 = _corner(c, t1, b), _corner(c, t2, b)
        va0, va1 = 3 * t1 + ka1, 3 * t2 + ka2
        vb0, vb1 = 3 * t1 + kb1, 3 * t2 + kb2
        pa0, pa1, pb0, pb1 = c.points[t1, ka1], c.points[t2, ka2], c.points[t1, kb1], c.points[t2, kb2]
        da = cw_delta(a, pa0, pa1)  # clockwise on a from T1 to T2
        db = cw_delta(b, pb1, pb0)  # clockwise on b from T2 to T1
        if (max(da, db) < DEGENERATE_ARC and np.linalg.norm(pa1 - pa0) < DEGENERATE_ARC
                and np.linalg.norm(pb1 - pb0) < DEGENERATE_ARC):
            # coplanar neighbours (four circles on one plane): the corridor is a bare edge;
            # merge its two vertex pairs so that T1 and T2 share that edge
            merge += [(va1, va0), (vb1, vb0)]
            per_circle_samples[(ci, a)] = per_circle_samples[(ci, b)] = np.zeros(0, np.int64)
            continue
        m = max(1, int(arc_segments(max(da, db))))
        cor_fns[ci] = _Corridor(c, a, b, (e1, e2), ang(a, pa0), da, ang(b, pb0), db, (apexes[0][ci], apexes[1][ci]))
        inner_a, inner_b = cor_fns[ci].ends(np.arange(1, m) / m)
        ids_a = np.arange(nv, nv + m - 1)
        ids_b = np.arange(nv + m - 1, nv + 2 * (m - 1))
        nv += 2 * (m - 1)
        verts += [inner_a, inner_b]
        vcircle += [np.full(m - 1, a), np.full(m - 1, b)]
        ra = np.concatenate([[va0], ids_a, [va1]])
        rb = np.concatenate([[vb0], ids_b, [vb1]])
        per_circle_samples[(ci, a)] = ids_a
        per_circle_samples[(ci, b)] = ids_b[::-1]
        q = np.arange(m)
        faces.append(np.stack([rb[q], ra[q], ra[q + 1]], axis=1))
        faces.append(np.stack([rb[q], ra[q + 1], rb[q + 1]], axis=1))
        s0, s1 = q / m, (q + 1) / m
        one, zero = np.ones(m), np.zeros(m)
        face_cor += [np.full(m, ci), np.full(m, ci)]
        face_par.append(np.stack([np.stack([s0, one], 1), np.stack([s0, zero], 1), np.stack([s1, zero], 1)], 1))
        face_par.append(np.stack([np.stack([s0, one], 1), np.stack([s1, zero], 1), np.stack([s1, one], 1)], 1))
    rings = []
    for i in range(n):
        parts = []
        for v, cor in zip(c.rings[i], c.ring_corridors[i]):
            parts.append([v])
            parts.append(per_circle_samples[(int(cor), i)])
        rings.append(np.concatenate(parts).astype(np.int64))
    vertices = np.concatenate(verts)
    vertex_circle = np.concatenate(vcircle).astype(np.int64)
    faces = np.concatenate(faces) if faces else np.zeros((0, 3), np.int64)
    # point circles: all their vertices are one point; keep the first
    remap = np.arange(len(vertices))
    for i in np.flatnonzero(point):
        remap[rings[i]] = rings[i][0]
    for x, y in merge:
        remap[remap == remap[x]] = remap[y]
    for i in range(n):
        r = remap[rings[i]]
        keep_r = r != np.roll(r, 1)  # consecutive duplicates on a ring: one vertex
        rings[i] = r[keep_r] if keep_r.any() else r[:1]
    faces = remap[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    return ChoccMesh(vertices, faces[keep].astype(np.int64), rings, vertex_circle,
                     np.concatenate(face_cor)[keep], np.concatenate(face_par)[keep], cor_fns)


class _Corridor:
    """The corridor between circles a and b of ``c`` as a function (s, t) -> points (§4), see
    ``corridor_ends``; ``ends(s)`` gives the generator's two ends on a and b."""

    def __init__(self, c: Chocc, a: int, b: int, frames, th_a0: float, da: float, th_b0: float, db: float,
                 apexes):
        e1, e2 = frames
        na, nb, aa, ab = c.normals[a], c.normals[b], c.alphas[a], c.alphas[b]
        self.args = (na, nb, aa, ab, (e1[a], e2[a]), (e1[b], e2[b]), th_a0, da, th_b0, db)
        self.apexes = apexes  # of the cones a -> b and b -> a (``cone_apex``)

    def ends(self, s) -> tuple[np.ndarray, np.ndarray]:
        return corridor_ends(*self.args, np.asarray(s, float), self.apexes)

    def __call__(self, s, t) -> np.ndarray:
        pa, pb = self.ends(s)
        return (1 - t)[:, None] * pa + t[:, None] * pb


def _corner(c: Chocc, tri: int, circle: int) -> int:
    return int(np.flatnonzero(c.triangles[tri] == circle)[0])


def cnt_segments(delta: float) -> int:
    """Crude Natural Tessellation (§6): one planar quad per corridor; arcs wider than 120°
    get more quads so that a disk's polygon never degenerates to a 2-gon."""
    return np.maximum(1, np.ceil(np.asarray(delta) / (2 * np.pi / 3) - 1e-9)).astype(np.int64)


def sampled_segments(segments: int):
    """Corridors as strips: about ``segments`` generators per full circle."""
    return lambda delta: np.maximum(1, np.ceil(np.asarray(delta) * segments / (2 * np.pi) - 1e-9)).astype(np.int64)


def pair_hull_mesh(normals, alphas, segments: int = 32) -> ChoccMesh:
    """The CHoCC case n = 2 (§3–4): two disks joined by one corridor that goes all the way
    round — the band of the elliptic cone through both circles, sampled as ``segments``
    generators through its apex. (Case n = 1 is the disk alone: no volume.) Faces include
    both disks; outward oriented."""
    normals = unit_rows(np.asarray(normals, float).reshape(2, 3))
    alphas = np.asarray(alphas, float).reshape(2)
    if np.arccos(np.clip(normals[0] @ normals[1], -1, 1)) <= alphas.sum():
        raise PleError("CHoCC: caps 0 and 1 overlap or touch")
    big, small = (0, 1) if alphas[0] >= alphas[1] else (1, 0)
    e1, e2 = perpendicular_frames(normals)
    th = np.arange(segments) * 2 * np.pi / segments
    ring_big = (np.cos(alphas[big]) * normals[big]
                + np.sin(alphas[big]) * (np.cos(th)[:, None] * e1[big] + np.sin(th)[:, None] * e2[big]))
    apex = corridor_apexes(normals, alphas, np.array([[big, small]]))
    ring_small = map_generators(ring_big[None], apex, normals[small:small + 1], alphas[small:small + 1])[0]
    verts = np.concatenate([ring_big, ring_small])
    k = np.arange(segments)
    nxt = (k + 1) % segments
    # the big disk's fan runs k -> k+1 (counter-clockwise about its normal), the band runs the
    # rings the other way, the small disk's fan again opposite to the band
    band = np.concatenate([np.stack([segments + nxt, nxt, k], 1), np.stack([segments + k, segments + nxt, k], 1)])
    disks = np.concatenate([np.stack([np.zeros(segments - 2, int), k[1:-1], k[2:]], 1),
                            np.stack([np.full(segments - 2, segments), segments + k[2:], segments + k[1:-1]], 1)])
    faces = np.concatenate([band, disks])
    vol = np.einsum("ij,ij->i", verts[faces[:, 0]], cross(verts[faces[:, 1]], verts[faces[:, 2]])).sum()
    if vol < 0:
        faces = faces[:, ::-1]
    ring_of = [k, segments + k] if big == 0 else [segments + k, k]
    rings = [r if (verts[r[1]] - verts[r[0]]) @ cross(normals[i], verts[r[0]]) < 0 else r[::-1]
             for i, r in enumerate(ring_of)]  # clockwise about each normal
    return ChoccMesh(verts, faces.astype(np.int64), rings, np.repeat([big, small], segments))
