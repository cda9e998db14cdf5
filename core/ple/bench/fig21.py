"""CHoCC paper Fig. 21 recomputed on the authors' own junctions (001_ §5–6).

Fig. 21 gives, for three junctions, the volume of the CHoCC, of its CNT and of the CNT
refined once and twice (§6) as fractions of the chopped inflated ball. The paper does not
give the junctions; the authors' Processing sketch does (Y. Wu, LatticeTriangulator,
github.com/diaogecp3/LatticeTriangulator: its commit d6a806b of 2020-02-09 adds these five
volumes; its junctions ``data/point_set/ps_hub_tessellation`` and ``ps_hub_tessellation_4``
are unchanged since 2019-07). Its measurements, recomputed here from the paper's definitions:

- the junction: a ball of radius 20 at the origin, each beam the cone-hull of it and another
  ball (centre, and a point on that ball's sphere);
- r⁺: §5's largest crossing of two beams' profile lines, times 1.03 ("slightly larger");
- the chopped inflated ball: S⁺ minus the caps beyond the contact disks (closed form);
- CHoCC and CNT: closed solids (disks included); the CNT has one planar quad per corridor;
- refined: §6's split (a triangle into 4, a corridor quad into 8 around its centroid), a new
  vertex on an edge of a circle's polygon snapped radially onto the circle, then every vertex
  centrally projected onto the hub: one outside the hub moves towards the centre to the first
  surface (ball or beam cone) it meets; one inside moves away from the centre to the first
  surface only when the centre lay inside the CNT before the point circle was added;
- and the refined volume is the signed volume of the tetrahedra from the ball's centre over
  the refined triangles alone: the contact disks are left out (the sketch's
  ``TriangleMesh.volume(centre)`` on ``toTriangleMesh()``, which keeps triangles only).

``fig_21_readings`` computes the three rows under the sketch's choices and with each choice
changed in turn; ``ple bench fig21`` prints it (``ple bench seeds`` includes it).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..algebra.elements import beam_distance
from ..meshing.achocc import contact_circles, hub_geometry, inflated_radius
from ..meshing.chocc import Chocc, chocc, corridor_mesh, sampled_segments
from ..meshing.hubs import hub_template

AUTHORS_BALL = 20.0
# each beam: the other ball's centre and a point on its sphere (the sketch's point-set files)
AUTHORS_JUNCTIONS = {
    "8 beams": np.array([
        [[-48.789055, 54.227524, -67.7324], [-62.51201, 47.777843, -60.96527]],
        [[-97.76306, 2.9246564, -20.249462], [-95.14398, -22.932217, -19.881508]],
        [[-15.076403, 83.29892, 52.803967], [-22.262205, 85.52763, 48.620815]],
        [[-33.151455, -12.028959, 93.32688], [-49.083553, -23.203936, 83.89386]],
        [[82.692474, 43.84343, 34.116005], [87.34088, 45.8481, 12.232269]],
        [[32.211075, 38.52889, -85.94388], [19.412212, 23.001804, -94.66596]],
        [[-1.8391433, -63.92346, -76.25778], [-24.745657, -72.31765, -63.925686]],
        [[29.800531, -91.58577, 26.121725], [40.885418, -90.74193, 7.548733]]]),
    "4 beams": np.array([
        [[-90.17559, -1.5702622, 42.756405], [-97.80307, -4.453002, 18.637728]],
        [[-33.151455, -12.028959, 93.32688], [-49.083553, -23.203936, 83.89386]],
        [[65.820946, 25.553055, 70.432365], [70.84761, 38.38611, 58.412415]],
        [[22.081291, -86.23245, 45.299774], [13.41157, -86.633, 47.964344]]]),
}
AUTHORS_INFLATION = 1.03  # the sketch's r⁺ over the largest profile crossing
POINT_CIRCLE = 1e-3  # radius of the infinitesimal circle of §6 over r⁺ (the sketch's)
ON_HUB = 1e-4  # a vertex this close to the hub is on it and is not projected (the sketch's)

# Fig. 21: junction, whether the point circle of §6 is added, the paper's fractions
FIG_21 = {
    "8 beams, even": ("8 beams", False, {"chocc": 0.893, "cnt": 0.816, "refined_1": 0.300, "refined_2": 0.292}),
    "4 beams, centre outside the CNT": ("4 beams", False,
                                        {"chocc": 0.230, "cnt": 0.179, "refined_1": 0.057, "refined_2": 0.047}),
    "4 beams, CNT adjusted": ("4 beams", True, {"chocc": 0.387, "cnt": 0.349, "refined_1": 0.126, "refined_2": 0.134}),
}
COLUMNS = ("chocc", "cnt", "refined_1", "refined_2")


@dataclass
class Junction:
    """One ball (centre at the origin, ``radius``) with beams to the balls at ``dirs`` (S, 3) ×
    ``lengths`` (S,) of radii ``other_radii`` (S,), its S⁺ (``r_plus``) and its circles on the
    unit sphere: ``normals`` (n, 3), half-angles ``alphas`` (n,), the S contact circles first."""

    radius: float
    dirs: np.ndarray
    other_radii: np.ndarray
    lengths: np.ndarray
    r_plus: float
    normals: np.ndarray
    alphas: np.ndarray

    def signed_distance(self, p: np.ndarray) -> np.ndarray:
        """Signed distance (V,) from points (V, 3) to the hub: the union of the cone-beams."""
        d = np.full(len(p), np.inf)
        for u, length, rho in zip(self.dirs, self.lengths, self.other_radii):
            d = np.minimum(d, beam_distance(p, np.zeros(3), self.radius, u * length, rho))
        return d

    def crossings(self, u: np.ndarray) -> np.ndarray:
        """Parameters tau (V, 2S + 2) where the lines tau·u (u: unit rows (V, 3)) cross the ball's
        sphere or a beam's cone between its tangent circles (NaN where they do not). The line
        passes through the cone's axis, so each half-line meets the cone once: at
        tau = ±r / (sin ψ cos φ ± cos ψ sin φ), ψ the angle to the axis, sin φ = (r − ρ) / L."""
        sphi = (self.radius - self.other_radii) / self.lengths
        cphi = np.sqrt(1 - sphi**2)
        cu = np.clip(u @ self.dirs.T, -1, 1)  # (V, S)
        su = np.sqrt(1 - cu**2)
        z0, z1 = self.radius * sphi, self.lengths + self.other_radii * sphi  # the cone's axial extent
        out = []
        for sign in (1.0, -1.0):
            den = su * cphi + sign * cu * sphi
            with np.errstate(divide="ignore"):
                tau = sign * self.radius / np.where(den > 0, den, np.nan)
            z = tau * cu
            out.append(np.where((z >= z0 - 1e-9) & (z <= z1 + 1e-9), tau, np.nan))
        ball = np.full((len(u), 1), self.radius)
        return np.concatenate(out + [ball, -ball], axis=1)


def authors_junction(name: str, inflation: float = AUTHORS_INFLATION) -> Junction:
    """The sketch's junction ``name`` with r⁺ = ``inflation`` × §5's largest profile crossing."""
    pairs = AUTHORS_JUNCTIONS[name]
    centres = pairs[:, 0]
    lengths = np.linalg.norm(centres, axis=1)
    dirs = centres / lengths[:, None]
    rho = np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=1)
    r_plus = inflated_radius(AUTHORS_BALL, dirs, rho, lengths) * inflation
    alphas, _, _ = contact_circles(AUTHORS_BALL, r_plus, dirs, rho, lengths)
    return Junction(AUTHORS_BALL, dirs, rho, lengths, r_plus, dirs, alphas)


def cnt(c: Chocc) -> tuple[np.ndarray, list, np.ndarray]:
    """§6's CNT of a CHoCC on the unit sphere: vertices (3t, 3) (vertex 3·triangle + corner),
    faces [triangles (t, 3), corridor quads (3n − 6, 4)] outward, and each vertex's circle (3t,)."""
    t = len(c.triangles)
    verts = c.points.reshape(-1, 3)
    a, b, t1, t2 = c.corridors.T
    corner = lambda tri, x: 3 * tri + np.argmax(c.triangles[tri] == x[:, None], axis=1)  # noqa: E731
    quads = np.stack([corner(t1, a), corner(t2, a), corner(t2, b), corner(t1, b)], axis=1)
    q = verts[quads]
    normal = np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])
    inward = np.einsum("mi,mi->m", normal, q.mean(axis=1) - verts.mean(axis=0)) < 0
    quads[inward] = quads[inward, ::-1]
    return verts, [np.arange(3 * t).reshape(t, 3), quads], c.triangles.reshape(-1)


def visible_faces(c: Chocc) -> np.ndarray:
    """Centroids (k, 3) of the CNT faces whose plane has the centre on its outer side (§6)."""
    verts, faces, _ = cnt(c)
    out = []
    for f in faces:
        p = verts[f]
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        out.append(p.mean(axis=1)[np.einsum("mi,mi->m", n, -p[:, 0]) >= 0])
    return np.concatenate(out)


def with_point_circle(j: Junction) -> Junction:
    """§6's fix: an infinitesimal circle where the ray from the centroid of the first visible
    CNT face through the centre meets S⁺ (the sketch takes its first; Fig. 21's junction has one)."""
    g = visible_faces(chocc(j.normals, j.alphas))[0]
    return replace(j, normals=np.vstack([j.normals, -g / np.linalg.norm(g)]),
                   alphas=np.append(j.alphas, np.arcsin(POINT_CIRCLE)))


def refine(verts: np.ndarray, faces: list, circle: np.ndarray, j: Junction, levels: int):
    """§6's refinement of a CNT (vertices (V, 3) in hub units): ``levels`` splits, a triangle into
    4 and a quad into 8 (4 corner triangles and 4 around its centroid); a new vertex on an edge
    whose ends lie on one circle is snapped radially onto it. Returns vertices, triangles (F, 3)
    and each vertex's circle (-1: none)."""
    for _ in range(levels):
        edges = np.concatenate([np.stack([f, np.roll(f, -1, axis=1)], axis=2).reshape(-1, 2) for f in faces])
        key = np.sort(edges, axis=1)
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        mids = 0.5 * (verts[uniq[:, 0]] + verts[uniq[:, 1]])
        ci = np.where(circle[uniq[:, 0]] == circle[uniq[:, 1]], circle[uniq[:, 0]], -1)
        on = ci >= 0
        n, a = j.normals[ci[on]], j.alphas[ci[on]]
        centre = (j.r_plus * np.cos(a))[:, None] * n
        radial = mids[on] - centre
        mids[on] = centre + (j.r_plus * np.sin(a))[:, None] * radial / np.linalg.norm(radial, axis=1, keepdims=True)
        nv = len(verts)
        new_faces, k = [], 0
        for f in faces:
            m = nv + inv[k:k + f.size].reshape(f.shape)  # midpoint of edge (f[:, i], f[:, i + 1])
            k += f.size
            if f.shape[1] == 3:
                new_faces += [np.stack([f[:, 0], m[:, 0], m[:, 2]], 1), np.stack([f[:, 1], m[:, 1], m[:, 0]], 1),
                              np.stack([f[:, 2], m[:, 2], m[:, 1]], 1), m]
            else:
                cid = nv + len(mids) + np.arange(len(f))
                new_faces += [np.stack([f[:, i], m[:, i], m[:, i - 1]], 1) for i in range(4)]
                new_faces += [np.stack([m[:, i], m[:, (i + 1) % 4], cid], 1) for i in range(4)]
                mids = np.concatenate([mids, verts[f].mean(axis=1)])
                ci = np.concatenate([ci, np.full(len(f), -1)])
        verts = np.concatenate([verts, mids])
        circle = np.concatenate([circle, ci])
        faces = [np.concatenate(new_faces)]
    return verts, faces[0], circle


def project(p: np.ndarray, j: Junction, both_ways: bool) -> np.ndarray:
    """§6's central projection of points (V, 3): one outside the hub moves towards the centre
    to the first surface it meets; with ``both_ways`` one inside moves away from the centre to
    the first surface (of the ball or a cone, inner ones included)."""
    dist = j.signed_distance(p)
    s = np.linalg.norm(p, axis=1)
    u = p / s[:, None]
    tau = j.crossings(u)
    with np.errstate(invalid="ignore"):
        below = np.where(tau < s[:, None], tau, -np.inf).max(axis=1)
        above = np.where(tau > s[:, None], tau, np.inf).min(axis=1)
    new = np.where(dist > ON_HUB, below, s)
    if both_ways:
        new = np.where((dist < -ON_HUB) & np.isfinite(above), above, new)
    return u * new[:, None]


def signed_volume(verts: np.ndarray, tris: np.ndarray) -> float:
    """Sum of the signed volumes of the tetrahedra (centre, triangle) over triangles (F, 3)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def disk_volume(verts: np.ndarray, circle: np.ndarray, j: Junction) -> float:
    """Volume of the cones from the centre over the polygons each circle's vertices bound,
    i.e. of the fans from each disk's centre (exact for vertices off its plane too). A point
    circle's polygon, 10⁻³ r⁺ across, is closed the same way (below 10⁻⁷ of the chopped ball)."""
    total = 0.0
    for i, (n, a) in enumerate(zip(j.normals, j.alphas)):
        ring = verts[circle == i]
        if len(ring) < 3:
            continue
        centre = j.r_plus * np.cos(a) * n
        e1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        e1 /= np.linalg.norm(e1)
        ring = ring[np.argsort(np.arctan2((ring - centre) @ np.cross(n, e1), (ring - centre) @ e1))]
        area = 0.5 * np.cross(ring - centre, np.roll(ring, -1, axis=0) - centre) @ n
        total += area.sum() * j.r_plus * np.cos(a) / 3.0
    return total


def chopped_ball_volume(r_plus: float, alphas: np.ndarray) -> float:
    """S⁺ minus the caps cut off by the contact disks' planes (caps of half-angles ``alphas``)."""
    h = r_plus * (1 - np.cos(np.asarray(alphas)))
    return float(4.0 / 3.0 * np.pi * r_plus**3 - (np.pi * h * h * (3 * r_plus - h) / 3.0).sum())


def chocc_volume(c: Chocc, r_plus: float, segments: int = 1024) -> float:
    """The CHoCC's volume: its corridors sampled with about ``segments`` generators per circle,
    closed by its disks."""
    m = corridor_mesh(c, sampled_segments(segments))
    return signed_volume(m.vertices * r_plus, np.concatenate([m.faces, m.disk_faces()]))


def fractions(j: Junction, contains: bool, closed: bool = False, onto_ball: bool = False) -> dict:
    """Fig. 21's four fractions of junction ``j``: CHoCC, CNT, CNT refined once and twice and
    projected (both ways if ``contains``: the centre lay in the CNT before any point circle;
    ``onto_ball``: onto the ball's sphere alone), the refined volumes without their disks as
    the sketch measures them, or with (``closed``)."""
    c = chocc(j.normals, j.alphas)
    unit, faces, circle = cnt(c)
    verts = unit * j.r_plus
    ball = chopped_ball_volume(j.r_plus, j.alphas)
    out = {"chocc": chocc_volume(c, j.r_plus) / ball,
           "cnt": (signed_volume(verts, np.concatenate([faces[0], faces[1][:, [0, 1, 2]], faces[1][:, [0, 2, 3]]]))
                   + disk_volume(verts, circle, j)) / ball}
    for levels in (1, 2):
        v, tris, ci = refine(verts, faces, circle, j, levels)
        v = v / np.linalg.norm(v, axis=1, keepdims=True) * j.radius if onto_ball else project(v, j, contains)
        out[f"refined_{levels}"] = (signed_volume(v, tris) + (disk_volume(v, ci, j) if closed else 0.0)) / ball
    return out


def actual_fraction(j: Junction, points: int = 1_200_000, seed: int = 0) -> tuple[float, float]:
    """The junction's own volume, which §6 says refinement approaches ("the actual value"): the
    hub (ball and beams) inside the chopped ball, as a fraction of it, by Monte Carlo over
    ``points`` uniform points of S⁺'s cube. Returns the fraction and twice its standard error."""
    p = np.random.default_rng(seed).uniform(-j.r_plus, j.r_plus, (points, 3))
    p = p[(np.linalg.norm(p, axis=1) <= j.r_plus) & np.all(p @ j.normals.T <= j.r_plus * np.cos(j.alphas), axis=1)]
    f = float(np.mean(j.signed_distance(p) <= 0))
    return f, 2 * float(np.sqrt(f * (1 - f) / len(p)))


def agrees(ours: float, theirs: float) -> bool:
    """Whether ``ours`` is the paper's 3-decimal figure, truncated or rounded."""
    return bool(np.floor(ours * 1000 + 1e-9) / 1000 == theirs or round(ours, 3) == theirs)


def centre_in_cnt(j: Junction) -> bool:
    return len(visible_faces(chocc(j.normals, j.alphas))) == 0


def ple_hub_meshes(j: Junction) -> dict:
    """The project's own hub meshes (``hub_template``: its CNT, refinement and off-centre fix)
    of junction ``j`` asked for S⁺ of radius ``j.r_plus``: r⁺ and whether the junction is clean
    to it, and the four fractions closed by the caps and without them."""
    geometry = hub_geometry(j.radius, j.dirs, j.other_radii, j.lengths, r_plus_min=j.r_plus)
    ball = chopped_ball_volume(geometry.r_plus, geometry.alphas)
    out = {"r_plus": geometry.r_plus, "clean": geometry.clean, "closed": {}, "without_disks": {}}
    for col, style, levels in zip(COLUMNS, ("chocc", "cnt", "refined", "refined"), (1, 1, 1, 2)):
        t = hub_template(np.zeros(3), j.radius, j.dirs * j.lengths[:, None], j.other_radii, style, levels, 256,
                         target=lambda _: geometry)
        out["without_disks"][col] = signed_volume(t.vertices, t.faces) / ball
        out["closed"][col] = signed_volume(t.vertices, np.concatenate([t.faces, *t.caps])) / ball
    return out


def fig_21_readings() -> dict:
    """The three rows of Fig. 21 under the sketch's choices (``sketch``) and with one choice
    changed at a time: the refined meshes closed by their disks; new vertices projected onto the
    ball alone; every fraction over the whole S⁺ instead of the chopped ball; r⁺ the minimal one
    (× 1.0001); for the adjusted row, the centre's containment tested after the point circle is
    added; and the project's own hub meshes of the same junctions (its off-centre fix always
    applies, so the middle row has none). Beside them, the actual junction's fraction."""
    rows = []
    for row, (name, fix, theirs) in FIG_21.items():
        out = {"row": row, "junction": name, "theirs": theirs}
        for reading, inflation in (("sketch", AUTHORS_INFLATION), ("minimal_r_plus", 1.0001)):
            j = authors_junction(name, inflation)
            contains = centre_in_cnt(j)
            if fix:
                out["visible_faces"] = len(visible_faces(chocc(j.normals, j.alphas)))
                j = with_point_circle(j)
            out[reading] = fractions(j, contains)
            if reading == "sketch":
                actual, two_sigma = actual_fraction(j)
                out.update(r_plus=j.r_plus, centre_in_cnt=contains, beams=len(j.dirs),
                           other_radii=j.other_radii.round(2).tolist(), lengths=j.lengths.round(2).tolist(),
                           actual_junction=actual, actual_junction_two_sigma=two_sigma)
                out["closed_refined"] = fractions(j, contains, closed=True)
                out["onto_ball"] = fractions(j, contains, onto_ball=True)
                whole = chopped_ball_volume(j.r_plus, j.alphas) / (4.0 / 3.0 * np.pi * j.r_plus**3)
                out["over_whole_s_plus"] = {k: v * whole for k, v in out["sketch"].items()}
                if fix:
                    out["containment_after_fix"] = fractions(j, centre_in_cnt(j))
                if fix or contains:
                    out["ple_hub_meshes"] = ple_hub_meshes(authors_junction(name, inflation))
        readings = [k for k, v in out.items() if isinstance(v, dict) and set(v) == set(COLUMNS) and k != "theirs"]
        out["agrees"] = {k: [c for c in COLUMNS if agrees(out[k][c], theirs[c])] for k in readings}
        rows.append(out)
    return {"rows": rows, "columns": list(COLUMNS)}


def add_arguments(p) -> None:
    """No options: the junctions are the authors'."""


def run(args) -> dict:
    return {"benchmark": "fig21", **fig_21_readings()}
