"""ACHoCC: a lattice as an assembly of CHoCCs (CHoCC paper, 001_ §5–6).

Each ball gets an inflated sphere S⁺ (same centre, radius r⁺) beyond which its incident
beams no longer interfere; each beam meets S⁺ in a contact circle bounding a disk; the
ball's *junction* (hub) is the CHoCC of its contact circles and each beam element is the
frustum of the beam's cone between its two disks. Beams are cone-beams: the convex hull of
their two balls.

Everything here is per hub, in the hub's own frame: centre at the origin, hub ball radius
``radius``, incident beams given by the unit direction ``dirs`` (S, 3) to the other ball,
its radius ``other_radii`` (S,) and the centre distance ``lengths`` (S,).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.elements import beam_distance
from ..algebra.vectors import perpendicular_frames
from ..errors import PleError
from .chocc import Chocc, chocc

INFLATE = 1e-4  # r⁺ "slightly larger than" the largest pairwise candidate (§5), relative
CENTRE_MARGIN = 1e-3  # the hub's CNT must contain its centre by this much (unit sphere) for central projection
MAX_FIX_CIRCLES = 8
MAX_DISK_REACH = 0.45  # a contact disk may sit at most this far along its beam (two ends never cross)
MIN_DISK_RADIUS = 0.25  # nor shrink below this fraction of the thinner ball
UNCLEAN_GAP = 1e-3  # radians between shrunk caps of an unclean junction
CENTRED_FACE = 1e-6  # a CNT face whose centroid is this close to the centre (unit sphere) gives no ray through it


class JunctionError(PleError):
    """A junction the ACHoCC cannot build: the geometric ``reason``, the incident ``beams`` it
    concerns (indices into the hub's beams) and, once ``hubs.hub_templates`` knows it, the ``hub``
    (a row of its call); the tessellator names the hub's node and beam-patterns. Pickles (its
    arguments are its state): template processes raise it too."""

    def __init__(self, reason: str, beams=(), hub: int | None = None):
        beams = tuple(int(b) for b in beams)
        super().__init__(reason, beams, hub)
        self.reason, self.beams, self.hub = reason, beams, hub

    def __str__(self) -> str:
        return self.reason


def check_junction(radius, dirs: np.ndarray, other_radii: np.ndarray, lengths: np.ndarray) -> None:
    """Raise ``JunctionError`` for the junctions no cone-beam model has (the degenerate cases
    the ACHoCC cannot mesh, each named by its geometry): a value that is not a finite number; a
    beam of length 0 (its two balls share a centre); a ball inside a beam's other ball (|r − r_o|
    ≥ L: the cone-beam is the larger ball, with no cone); two beams leaving in the same direction
    (one beam-pattern repeated, or balls in line: the nearer beam lies inside the other)."""
    if not (np.isfinite(radius) and np.all(np.isfinite(dirs)) and np.all(np.isfinite(other_radii))
            and np.all(np.isfinite(lengths))):
        bad = np.flatnonzero(~(np.isfinite(dirs).all(axis=1) & np.isfinite(other_radii) & np.isfinite(lengths)))
        raise JunctionError("a radius, centre or beam direction is not a finite number", bad)
    zero = np.flatnonzero(lengths <= 0)
    if len(zero):
        raise JunctionError("a beam has length 0 (its two balls share a centre)", zero[:1])
    inside = np.flatnonzero(np.abs(radius - other_radii) >= lengths)
    if len(inside):
        k = inside[0]
        which = "this hub's ball inside the other" if other_radii[k] > radius else "the other ball inside this hub's"
        raise JunctionError(f"a ball lies inside the other ball of its beam ({which}: |r1 − r2| = "
                            f"{abs(radius - other_radii[k]):.6g} ≥ length {lengths[k]:.6g}; the cone-beam "
                            "is undefined)", [k])
    if len(dirs) > 1:
        i, j = np.triu_indices(len(dirs), 1)
        sin_t = np.linalg.norm(np.cross(dirs[i], dirs[j]), axis=1)
        cos_t = np.einsum("mi,mi->m", dirs[i], dirs[j])
        same = np.flatnonzero(((sin_t < 1e-9) & (cos_t > 0)) | (cos_t >= 1.0))  # as inflated_radius sees them
        if len(same):
            k = same[0]
            raise JunctionError("two beams leave the ball in the same direction (a beam-pattern repeated, or "
                                "balls in line: one beam lies inside the other)", [i[k], j[k]])


def beam_profile(radius, other_radii, lengths):
    """sin and cos of the half-angle phi of each beam's cone (positive: narrowing away from
    the hub): sin phi = (r − r_other) / L (the cone tangent to both balls)."""
    s = (radius - other_radii) / lengths
    if np.any(np.abs(s) >= 1):
        raise JunctionError("a ball lies inside a beam's other ball (cone-beam undefined)",
                            np.flatnonzero(np.abs(s) >= 1)[:1])
    return s, np.sqrt(1 - s * s)


def inflated_radius(radius: float, dirs: np.ndarray, other_radii: np.ndarray, lengths: np.ndarray) -> float:
    """r⁺ of §5: the largest distance from the centre at which the profiles of two incident
    beams intersect, in the plane of their axes (line-line intersection), or ``radius``."""
    s = len(dirs)
    if s < 2:
        return float(radius)
    sphi, cphi = beam_profile(radius, other_radii, lengths)
    i, j = np.triu_indices(s, 1)
    d1, d2 = dirs[i], dirs[j]
    cos_t = np.clip(np.einsum("mi,mi->m", d1, d2), -1, 1)
    sin_t = np.sqrt(1 - cos_t**2)
    same = np.flatnonzero((sin_t < 1e-9) & (cos_t > 0))
    if len(same):
        raise JunctionError("two beams of one ball point the same way", [i[same[0]], j[same[0]]])
    # 2D frame (x along d1, y towards d2); profile k: n_k·p = r, n_k = sin(phi_k) d_k + cos(phi_k) w_k,
    # w_1 = (0, 1), w_2 = the normal of d2 towards d1 = (sin t, -cos t)
    n1 = np.stack([sphi[i], cphi[i]], axis=1)
    d2xy = np.stack([cos_t, sin_t], axis=1)
    w2 = np.stack([sin_t, -cos_t], axis=1)
    n2 = sphi[j, None] * d2xy + cphi[j, None] * w2
    det = n1[:, 0] * n2[:, 1] - n1[:, 1] * n2[:, 0]
    safe = np.abs(det) > 1e-12
    det = np.where(safe, det, 1.0)
    px = radius * (n2[:, 1] - n1[:, 1]) / det
    py = radius * (n1[:, 0] - n2[:, 0]) / det
    forward = safe & (px > 0) & (px * d2xy[:, 0] + py * d2xy[:, 1] > 0)
    cand = np.where(forward, np.hypot(px, py), radius)
    return float(max(radius, cand.max()))


def contact_circles(radius, r_plus, dirs, other_radii, lengths, strict: bool = True):
    """Half-angles (S,) of the contact circles of the beams on S⁺ (unit-sphere cone angles),
    and the axial position (S,) and radius (S,) of each contact disk (in world units)."""
    sphi, cphi = beam_profile(radius, other_radii, lengths)
    s = np.sqrt(max(r_plus**2 - radius**2, 0.0))
    x = radius * sphi + s * cphi  # tangent point r n plus s along the profile line
    y = radius * cphi - s * sphi
    if strict and (np.any(y <= 0) or np.any(x >= lengths)):
        raise JunctionError("a beam is too short for its junction (r+ passes its far end)",
                            np.flatnonzero((y <= 0) | (x >= lengths))[:1])
    return np.arctan2(np.maximum(y, 0.0), x), x, y


def disk_reach(radius, sphi, cphi, other_radii, lengths) -> np.ndarray:
    """Per beam (..., S), the largest s (distance from the tangent point along the profile) at
    which its contact disk stays in the first MAX_DISK_REACH of the beam (the two ends never
    cross) and keeps at least MIN_DISK_RADIUS of the thinner ball's radius. ``radius``: a float
    or (H, 1)."""
    # axial x = r sin(phi) + s cos(phi) ≤ reach·L, radius y = r cos(phi) − s sin(phi) ≥ m·min(r, r_o)
    s_max = (MAX_DISK_REACH * lengths - radius * sphi) / cphi
    y_min = MIN_DISK_RADIUS * np.minimum(radius, other_radii)
    s_y = np.where(sphi > 0, (radius * cphi - y_min) / np.where(sphi > 0, sphi, 1.0), np.inf)
    return np.clip(np.minimum(s_max, s_y), 0.0, None)


def _max_inflation(radius, other_radii, lengths) -> float:
    """The largest r⁺ for which every contact disk stays within its ``disk_reach``."""
    sphi, cphi = beam_profile(radius, other_radii, lengths)
    return float(np.sqrt(radius**2 + disk_reach(radius, sphi, cphi, other_radii, lengths).min() ** 2))


def pulled_circles(radius, r_plus, sphi, cphi, reach, theta):
    """Contact circles of a junction whose S⁺ passes the far end of a short beam: each beam's
    disk where S⁺ meets it, or nearer, at its ``disk_reach`` (s = min(sqrt(r⁺² − r²), reach)).
    The circles then lie at their own distances rho from the centre, not on one sphere; the
    junction is the CHoCC of their cones of directions (half-angles alpha), each vertex at its
    circle's distance, and stays star-shaped from the centre. radius, r_plus: floats or (H, 1);
    sphi, cphi, reach (..., S); theta (..., S, S) the angles between beams (inf on the
    diagonal). Returns alphas, rho (..., S) and ok (...): every disk real, in front of the
    centre, and the caps of directions disjoint (else the beams' cones cross nearer than the
    disks and the junction is unclean)."""
    s = np.minimum(np.sqrt(np.maximum(r_plus**2 - radius**2, 0.0)), reach)
    x = radius * sphi + s * cphi
    y = radius * cphi - s * sphi
    alphas = np.arctan2(np.maximum(y, 0.0), x)
    gap = theta - (alphas[..., :, None] + alphas[..., None, :])
    ok = np.all((y > 0) & (x > 0), axis=-1) & np.all(gap > 1e-9, axis=(-2, -1))
    return alphas, np.hypot(x, y), ok


@dataclass
class HubGeometry:
    """A junction of the ACHoCC on its unit sphere (scale by ``r_plus``).

    ``chocc`` holds the S real contact circles first, then point circles added so that the
    hub has triangles (n ≤ 2) and contains its centre (the off-centre fix of §6). ``clean`` is
    False when the lattice violates the ACHoCC assumption (junctions of neighbouring balls
    would overlap): r⁺ is then capped inside the beams and the caps shrunk to stay disjoint, so
    the mesh stays closed but its contact rings lie inside the beams, not on them."""

    radius: float
    r_plus: float
    dirs: np.ndarray
    other_radii: np.ndarray
    lengths: np.ndarray
    chocc: Chocc
    slots: int
    clean: bool = True
    alphas: np.ndarray | None = None
    base_triangles: np.ndarray | None = None  # CHoCC triangles before the off-centre fix (a hint for neighbours)
    rho: np.ndarray | None = None

    @property
    def pulled(self) -> bool:
        """Whether a short beam pulled a contact circle in from S⁺."""
        return self.rho is not None

    def circle_radii(self) -> np.ndarray:
        """Distance (S,) of each contact circle from the centre: r⁺, or ``rho`` if pulled in."""
        return np.full(self.slots, self.r_plus) if self.rho is None else self.rho

    def disk_axial(self) -> np.ndarray:
        """Axial position (S,) of each contact disk's centre along its beam."""
        return self.circle_radii() * np.cos(self.alphas)

    def exit_distance(self, u: np.ndarray) -> np.ndarray:
        """Distance (V,) from the centre along unit rays ``u`` (V, 3) to the boundary of the
        exact lattice near this ball: the union of its incident cone-beams (or the ball).
        Each cone-beam contains the centre and is convex, so the union is star-shaped from
        it and the exit is the largest of the per-beam exits, each in closed form: on the
        hub ball's cap (cos < sin phi), on the cone (up to the far tangent circle), or on
        the far ball."""
        return exit_distances(u[None], np.array([self.radius]), self.dirs[None], self.other_radii[None],
                              self.lengths[None])[0]

    def signed_distance(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (V,) from points (V, 3) to the union of the ball and its beams."""
        d = np.linalg.norm(p, axis=1) - self.radius
        for k in range(len(self.dirs)):
            d = np.minimum(d, beam_distance(p, np.zeros(3), self.radius, self.dirs[k] * self.lengths[k],
                                             self.other_radii[k]))
        return d


def exit_distances(u: np.ndarray, radius: np.ndarray, dirs: np.ndarray, other_radii: np.ndarray,
                   lengths: np.ndarray) -> np.ndarray:
    """``HubGeometry.exit_distance`` of H hubs at once: rays u (H, V, 3), hub radii (H,), beams
    dirs (H, S, 3), other_radii (H, S), lengths (H, S). Returns (H, V)."""
    r = np.asarray(radius, float)[:, None]
    t = np.broadcast_to(r, u.shape[:2])
    if not dirs.shape[1]:
        return t.copy()
    sphi, cphi = beam_profile(r, other_radii, lengths)  # (H, S)
    sphi, cphi, ln, ro = sphi[:, None], cphi[:, None], lengths[:, None], other_radii[:, None]
    cu = np.clip(np.einsum("hvi,hsi->hvs", u, dirs), -1, 1)  # (H, V, S)
    su = np.sqrt(1 - cu**2)
    den = sphi * cu + cphi * su
    t_cone = np.where(den > 0, r[..., None] / np.where(den > 0, den, 1.0), np.inf)
    x_far = ln + ro * sphi  # axial end of the cone part
    disc = np.maximum(ln**2 * cu**2 - ln**2 + ro**2, 0)
    t_ball = ln * cu + np.sqrt(disc)
    t_k = np.where(cu <= sphi, r[..., None], np.where(t_cone * cu <= x_far, t_cone, t_ball))
    return np.maximum(t, t_k.max(axis=-1))


def _seed_points(dirs: np.ndarray) -> np.ndarray:
    """Point circles for hubs with fewer than three beams (CHoCC cases n = 0, 1, 2)."""
    if len(dirs) == 0:  # an isolated ball: the octahedron
        return np.concatenate([np.eye(3), -np.eye(3)])
    if len(dirs) == 1:  # a beam end: a tripod on the far hemisphere
        d = dirs[0]
        e1 = perpendicular_frames(d[None])[0][0]
        e2 = np.cross(d, e1)
        ang = np.arange(3) * 2 * np.pi / 3
        return -0.5 * d + 0.866 * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    if len(dirs) == 2:  # two beams: near the poles of their great circle, tilted away from the
        # beams (exact poles would put the centre on the face through both)
        m = np.cross(dirs[0], dirs[1])
        m = m / np.linalg.norm(m) if np.linalg.norm(m) > 1e-9 else perpendicular_frames(dirs[:1])[0][0]
        b = dirs[0] + dirs[1]
        b = b / np.linalg.norm(b) if np.linalg.norm(b) > 1e-6 else np.cross(dirs[0], m)
        p = np.stack([m - 0.3 * b, -m - 0.3 * b])
        return p / np.linalg.norm(p, axis=1, keepdims=True)
    return np.zeros((0, 3))


def _visible_face(c: Chocc) -> tuple[float, np.ndarray, np.ndarray]:
    """Smallest signed distance of the centre below the planes of the CNT faces (triangles and
    planar corridor quads), and the centroid and outward normal of the face achieving it."""
    # rounded so that symmetric ties pick the first face whatever the round-off (deterministic
    # fixes: a similar copy of the lattice gets the same hubs)
    h = np.round(np.cos(c.plane_alphas), 9)
    i = int(np.argmin(h))
    best, centroid, normal = float(h[i]), c.points[i].mean(axis=0), c.plane_normals[i]
    if len(c.corridors):
        a, b, t1, t2 = c.corridors.T
        corner = lambda t, x: np.argmax(c.triangles[t] == x[:, None], axis=1)  # noqa: E731
        q = np.stack([c.points[t1, corner(t1, a)], c.points[t2, corner(t2, a)],
                      c.points[t2, corner(t2, b)], c.points[t1, corner(t1, b)]], axis=1)  # (m, 4, 3)
        # outward: the CCW quad (b0, a0, a1, b1)'s diagonals
        nrm = np.cross(q[:, 1] - q[:, 3], q[:, 2] - q[:, 0])
        ln = np.linalg.norm(nrm, axis=1)
        ok = ln > 1e-12
        if ok.any():
            hq = np.where(ok, np.round(np.einsum("mi,mi->m", nrm, q[:, 0]) / np.where(ok, ln, 1.0), 9), np.inf)
            j = int(np.argmin(hq))
            if hq[j] < best:
                best, centroid, normal = float(hq[j]), q[j].mean(axis=0), nrm[j] / ln[j]
    return best, centroid, normal


def hub_geometry(radius: float, dirs, other_radii, lengths, hint=None, r_plus_min: float = 0.0) -> HubGeometry:
    """The junction of one ball: r⁺, contact circles, CHoCC with the off-centre fix (§5–6).
    ``hint``: the ``base_triangles`` of a similar hub (see ``ple.chocc.chocc``). ``r_plus_min``
    asks for a larger S⁺ (a fillet's reach, ``ple.meshing.fillet``), capped where the contact
    disks would leave the first part of their beams."""
    dirs = np.asarray(dirs, float).reshape(-1, 3)
    other_radii = np.asarray(other_radii, float).reshape(-1)
    lengths = np.asarray(lengths, float).reshape(-1)
    check_junction(radius, dirs, other_radii, lengths)
    r_plus = inflated_radius(radius, dirs, other_radii, lengths) * (1 + INFLATE)
    if len(dirs):  # a beam widening away from the ball meets S⁺ in front of the centre only beyond r / cos(phi)
        _, cphi = beam_profile(radius, other_radii, lengths)
        r_plus = max(r_plus, radius / cphi.min() * (1 + 1e-2))
    clean, rho = True, None
    if len(dirs):
        limit = _max_inflation(radius, other_radii, lengths)
        if r_plus > limit and r_plus_min <= 0:  # a short beam: pull its circle in, if the caps stay apart
            sphi, cphi = beam_profile(radius, other_radii, lengths)
            theta = np.arccos(np.clip(dirs @ dirs.T, -1, 1))
            np.fill_diagonal(theta, np.inf)
            pa, prho, ok = pulled_circles(radius, r_plus, sphi, cphi,
                                          disk_reach(radius, sphi, cphi, other_radii, lengths), theta)
            if ok:
                alphas, rho = pa, prho
        if rho is None and r_plus > limit:  # unclean: neighbouring junctions would overlap; stay inside the beams
            r_plus, clean = max(limit, radius), False
        elif rho is None:
            r_plus = max(r_plus, min(r_plus_min, limit))
    if rho is None:
        alphas, _, _ = contact_circles(radius, r_plus, dirs, other_radii, lengths, strict=clean)
    if len(dirs) > 1 and rho is None:
        theta = np.arccos(np.clip(dirs @ dirs.T, -1, 1))
        np.fill_diagonal(theta, np.inf)
        gap = theta - (alphas[:, None] + alphas[None, :])
        while clean and gap.min() <= 1e-9:  # caps still touching at r⁺ (round-off): inflate a little more
            if r_plus * 1.001 > limit:
                clean = False
                break
            r_plus *= 1.001
            alphas, _, _ = contact_circles(radius, r_plus, dirs, other_radii, lengths)
            gap = theta - (alphas[:, None] + alphas[None, :])
        if gap.min() <= 1e-9:  # caps overlap at the allowed r⁺: shrink each to its share
            share = (theta - UNCLEAN_GAP) * alphas[:, None] / np.maximum(alphas[:, None] + alphas[None, :], 1e-300)
            alphas = np.clip(np.minimum(alphas, share.min(axis=1)), 0.0, None)
            clean = False
    normals = np.concatenate([dirs, _seed_points(dirs)])
    alist = np.concatenate([alphas, np.zeros(len(normals) - len(dirs))])
    c = chocc(normals, alist, hint)
    base_triangles = c.triangles
    # off-centre fix (§6): while the centre is outside the CNT, add a point circle where the
    # ray from the centroid of a face visible from the centre, through the centre, meets S⁺
    for _ in range(MAX_FIX_CIRCLES):
        h, g, nrm = _visible_face(c)
        if h > CENTRE_MARGIN:
            break
        # a face through the centre with its centroid there (a T-junction: the CNT quad between two
        # antipodal contact circles, beside a third beam) has no ray from its centroid through the
        # centre (round-off would pick one, or 0/0 a NaN): its outward normal is free, as below
        gn = np.linalg.norm(g)
        p = -g / gn if gn > CENTRED_FACE else nrm
        if np.any(np.arccos(np.clip(normals @ p, -1, 1)) <= alist + 1e-6):
            # the ray's exit lies in a cap: use the face's outward normal instead (its cap of
            # half-angle acos(h) ≥ 90° holds no circle, so the point is free and lifts the face)
            p = nrm
        if np.any(np.arccos(np.clip(normals @ p, -1, 1)) <= alist + 1e-6):
            break
        normals = np.concatenate([normals, p[None]])
        alist = np.concatenate([alist, [0.0]])
        c = chocc(normals, alist)
    return HubGeometry(float(radius), float(r_plus), dirs, other_radii, lengths, c, len(dirs), clean, alphas,
                       base_triangles, rho)
