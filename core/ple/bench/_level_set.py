"""The ``level_set`` baseline of ``ple bench unclean``: manifold3d's ``Manifold.level_set`` of a
lattice's exact solid (the union of its balls and of the round cones that are their beams' hulls),
at the edge length that puts its volume within ``TARGET`` of the exact union's.

manifold3d samples a signed distance function on a body-centred cubic grid and meshes it by
marching tetrahedra; the function is a Python callable, called once per grid point. Here it is
the exact signed distance of the union (positive inside), found through a hash of cells holding
the elements whose box, grown by ``reach``, meets them: a point farther than that from every
element gets -``reach`` (the crossings are interpolated between grid points at most one edge from
the surface, whose values are exact). The edge length is calibrated on the lattice's corner block
of 2³ groups: the largest of ``EDGES`` (fractions of the smallest radius) whose mesh's volume is
within ``TARGET`` of that block's exact volume (``reference_volume``: a ``CALIBRATION_SEGMENTS``
union divided by its balls' deficit).
"""

from __future__ import annotations

import math

import numpy as np

TARGET = 0.01  # relative volume error of the baseline (issue: "level_set at 1 % volume")
EDGES = (1.2, 1.0, 0.8, 0.6, 0.45, 0.33, 0.25, 0.18)  # edge lengths tried, as fractions of the smallest ball radius
CALIBRATION_SEGMENTS = 96  # of the reference union's balls: its volume is 1 - O((π/96)²) ≈ 0.2 % under


def round_cone_distance(p, a, b, ra: float, rb: float) -> float:
    """Signed distance (negative inside) from p to the convex hull of the balls (a, ra) and (b, rb)
    (a round cone): exact, from the projection of p on the axis and the cone's slant (the tangent
    line of the two circles in the plane of p and the axis)."""
    bax, bay, baz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    l2 = bax * bax + bay * bay + baz * baz
    if l2 <= 0.0:
        return math.dist(p, a) - max(ra, rb)
    rr = ra - rb
    a2 = l2 - rr * rr
    if a2 <= 0.0:  # one ball holds the other
        return min(math.dist(p, a) - ra, math.dist(p, b) - rb)
    pax, pay, paz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    y = pax * bax + pay * bay + paz * baz
    z = y - l2
    qx, qy, qz = pax * l2 - bax * y, pay * l2 - bay * y, paz * l2 - baz * y
    x2 = qx * qx + qy * qy + qz * qz
    y2, z2 = y * y * l2, z * z * l2
    k = math.copysign(rr * rr * x2, rr)
    if math.copysign(a2 * z2, z) > k:
        return math.sqrt(x2 + z2) / l2 - rb
    if math.copysign(a2 * y2, y) < k:
        return math.sqrt(x2 + y2) / l2 - ra
    return (math.sqrt(x2 * a2 / l2) + y * rr) / l2 - ra


class UnionDistance:
    """The signed distance (positive inside) of a union of balls (center (N, 3), radius (N,)) and
    of the round cones of ``beam_nodes`` (M, 2), callable at a point (module docstring)."""

    def __init__(self, center, radius, beam_nodes, reach: float):
        c = np.asarray(center, float).reshape(-1, 3)
        r = np.asarray(radius, float).reshape(-1)
        bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
        self.reach = float(reach)
        ends = np.concatenate([np.stack([np.arange(len(c))] * 2, axis=1), bn])
        lo = np.minimum(c[ends[:, 0]] - r[ends[:, 0], None], c[ends[:, 1]] - r[ends[:, 1], None]) - reach
        hi = np.maximum(c[ends[:, 0]] + r[ends[:, 0], None], c[ends[:, 1]] + r[ends[:, 1], None]) + reach
        self.cell = float(np.median(hi - lo)) or 1.0
        self.origin = lo.min(axis=0)
        cells: dict = {}
        a = np.floor((lo - self.origin) / self.cell).astype(int)
        b = np.floor((hi - self.origin) / self.cell).astype(int)
        elements = [(tuple(c[x]), tuple(c[y]), float(r[x]), float(r[y])) for x, y in ends.tolist()]
        for e in range(len(ends)):
            for key in np.ndindex(*(b[e] - a[e] + 1)):
                cells.setdefault((a[e][0] + key[0], a[e][1] + key[1], a[e][2] + key[2]), []).append(elements[e])
        self.cells = cells

    def __call__(self, x: float, y: float, z: float) -> float:
        o, s = self.origin, self.cell
        near = self.cells.get((int((x - o[0]) // s), int((y - o[1]) // s), int((z - o[2]) // s)))
        if not near:
            return -self.reach
        p = (x, y, z)
        return -min(round_cone_distance(p, a, b, ra, rb) for a, b, ra, rb in near)


def level_set_mesh(center, radius, beam_nodes, edge: float):
    """manifold3d's level-set mesh of the union at edge length ``edge`` (a Manifold)."""
    import manifold3d  # noqa: PLC0415 - the baseline's package

    sdf = UnionDistance(center, radius, beam_nodes, 2 * edge)
    c, r = np.asarray(center, float).reshape(-1, 3), np.asarray(radius, float).reshape(-1)
    lo, hi = (c - r[:, None]).min(axis=0) - edge, (c + r[:, None]).max(axis=0) + edge
    return manifold3d.Manifold.level_set(sdf, [*lo.tolist(), *hi.tolist()], edge)


def unit_deficit(segments: int) -> float:
    """The volume of manifold3d's polygonal unit ball of ``segments`` over the exact ball's
    (0.978 at 32 segments, 0.997 at 96)."""
    import manifold3d  # noqa: PLC0415 - the baseline's package

    return float(manifold3d.Manifold.sphere(1.0, segments).volume()) / (4 * math.pi / 3)


def element_union(center, radius, beam_nodes, segments: int):
    """One manifold3d batch union of every ball (a ``segments``-segment sphere) and every beam (the
    hull of its two balls): the baseline of ``ple bench unclean`` (a lazy Manifold)."""
    import manifold3d  # noqa: PLC0415 - the baseline's package

    unit = manifold3d.Manifold.sphere(1.0, segments)
    balls = [unit.scale([float(q)] * 3).translate(list(map(float, p))) for p, q in zip(center, radius)]
    parts = balls + [manifold3d.Manifold.batch_hull([balls[a], balls[b]]) for a, b in np.asarray(beam_nodes).tolist()]
    return manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add)


def reference_volume(center, radius, beam_nodes, segments: int = CALIBRATION_SEGMENTS) -> float:
    """The exact union's volume, from ``element_union`` at ``segments`` divided by the polygonal
    ball's volume deficit (``unit_deficit``)."""
    return float(element_union(center, radius, beam_nodes, segments).volume()) / unit_deficit(segments)


def calibrated_edge(ev_block, target: float = TARGET) -> dict:
    """The largest edge of ``EDGES`` (times the block's smallest radius) whose level-set volume is
    within ``target`` of the block's exact volume; with each try's error."""
    c, r, bn = ev_block.center, ev_block.radius, ev_block.beam_nodes
    exact = reference_volume(c, r, bn)
    tries = []
    for frac in EDGES:
        edge = frac * float(np.min(r))
        err = float(level_set_mesh(c, r, bn, edge).volume()) / exact - 1.0
        tries.append({"edge": edge, "relative_volume_error": err})
        if abs(err) <= target:
            return {"edge": edge, "tries": tries, "block_volume": exact}
    return {"edge": tries[-1]["edge"], "tries": tries, "block_volume": exact, "target_missed": True}
