"""An independent CLG reference for the tests: ``ple-clg/1`` dicts evaluated by brute force — every
primitive of every chunk copy, node positions by explicit matrix powers, cone-beams as the union of
the balls interpolated between their end balls, compound primitives expanded here from their
definitions in thesis §5.4, Booleans on membership arrays, beam frames by scipy rotations."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation as SciRot

GOLD = (np.sqrt(5) - 1) / 2


def group_matrix(mats, g) -> np.ndarray:
    """G · W^k · V^j · U^i by numpy matrix powers (negative powers through the inverse)."""
    u, v, w, place = mats
    # keyed by the matrices' bytes: an id() would be reused by a later pattern's fresh arrays
    tag = b"".join(np.ascontiguousarray(m, dtype=float).tobytes() for m in mats)
    out = []
    for i, j, k in g:
        key = (tag, int(i), int(j), int(k))
        if key not in _MATS:
            _MATS[key] = (place @ np.linalg.matrix_power(w, int(k)) @ np.linalg.matrix_power(v, int(j))
                          @ np.linalg.matrix_power(u, int(i)))
        out.append(_MATS[key])
    return np.array(out)


_MATS: dict = {}


def node(ref, g, pat):
    """Centres (m, 3) and radii (m,) of node ref (di, dj, dk, n) in the copies at groups g."""
    d = np.asarray(ref[:3])
    n = ref[3]
    m = group_matrix(pat["mats"], np.asarray(g) + d)
    c = np.einsum("mab,b->ma", m[:, :3, :3], pat["centers"][n]) + m[:, :3, 3]
    f = np.abs(np.linalg.det(m[:, :3, :3])) ** (1 / 3)
    return c, f * pat["radii"][n]


def beam_f(p, ca, ra, cb, rb, iters: int = 50) -> np.ndarray:
    """min over t in [0, 1] of |p - c(t)| - r(t): the distance to the hull outside, ≤ 0 inside
    (a convex function of t, minimized by golden-section search: one new value of t per step, the
    other inner point kept; 50 steps leave t within 4e-11, far below the tests' 1e-7 near surfaces)."""
    lo, hi = np.zeros(len(p)), np.ones(len(p))

    def f(t):
        d = p - (ca + t[:, None] * (cb - ca))
        return np.sqrt(np.einsum("ij,ij->i", d, d)) - (ra + t * (rb - ra))
    a, b = hi - GOLD * (hi - lo), lo + GOLD * (hi - lo)
    fa, fb = f(a), f(b)
    for _ in range(iters):
        left = fa < fb  # the minimum lies in [lo, b]: b becomes the new upper inner point, else a the lower
        hi = np.where(left, b, hi)
        lo = np.where(left, lo, a)
        a, b = np.where(left, hi - GOLD * (hi - lo), b), np.where(left, a, lo + GOLD * (hi - lo))
        new = f(np.where(left, a, b))
        fa, fb = np.where(left, new, fb), np.where(left, fa, new)
    return np.minimum.reduce([fa, fb, f(lo), f(np.zeros(len(p))), f(np.ones(len(p)))])


def expand(e, pat):
    """Compound primitives into ball/beam/ops (thesis §5.4), with this module's own rules."""
    (key, val), = e.items()
    if key in ("union", "intersection", "difference"):
        return {key: [expand(x, pat) for x in val]}
    mat = val.get("material")

    def beam(a, b, s1, s2):
        out = {"beam": {"from": a, "to": b, "scale": [s1, s2]}}
        if mat is not None:
            out["beam"]["material"] = mat
        return out

    def hub(nd, s1, s2):
        bs = []
        for (n1, n2, off) in pat["beams"]:
            if n1 == nd[3]:
                bs.append(beam(nd, [nd[0] + off[0], nd[1] + off[1], nd[2] + off[2], n2], s1, s2))
            if n2 == nd[3]:
                bs.append(beam(nd, [nd[0] - off[0], nd[1] - off[1], nd[2] - off[2], n1], s1, s2))
        return {"union": bs}
    if key == "hollow_beam":
        s1, s2 = val["scale"]
        h = val["hollow"]
        return {"difference": [beam(val["from"], val["to"], s1, s2), beam(val["from"], val["to"], h * s1, h * s2)]}
    if key == "extended_hub":
        return hub(val["node"], *val["scale"])
    if key == "connector":
        ball = {"ball": {"node": val["node"], "scale": val["reach"]}}
        if mat is not None:
            ball["ball"]["material"] = mat
        return {"difference": [{"intersection": [ball, hub(val["node"], val["outer"], val["outer"])]},
                               hub(val["node"], val["inner"], val["inner"])]}
    return e


def pattern_of(clg) -> dict:
    """The pattern's matrices, template balls and beam-patterns, read from the loaded lattice."""
    lat = clg.pattern
    return {"mats": (lat.U.matrix, lat.V.matrix, lat.W.matrix, lat.placement.matrix),
            "centers": lat.template_centers, "radii": lat.template_radii, "counts": lat.counts,
            "beams": [(b.n1, b.n2, (b.di, b.dj, b.dk)) for b in lat.beams]}


_PATTERNS: dict = {}


def frame(kind, ca, ra, cb):
    if kind == "world":
        return np.zeros_like(ca), np.broadcast_to(np.eye(3), (len(ca), 3, 3)), np.ones(len(ca))
    if cb is None:
        return ca, np.broadcast_to(np.eye(3), (len(ca), 3, 3)), ra
    d = cb - ca
    f = np.linalg.norm(d, axis=1)
    e = d / f[:, None]
    axis = np.cross(np.array([1.0, 0, 0]), e)
    s = np.linalg.norm(axis, axis=1)
    ang = np.arctan2(s, e[:, 0])
    axis = np.where(s[:, None] > 1e-15, axis / np.where(s > 1e-15, s, 1)[:, None], np.array([0, 0, 1.0]))
    return ca, SciRot.from_rotvec(axis * ang[:, None]).as_matrix(), f


def inside(data, clg, p, tol_out: list | None = None) -> np.ndarray:
    """Brute-force membership of points p (q, 3) in the CLG ``data`` (``clg`` = its loaded form,
    for the pattern matrices and the replacing CLGs); ``tol_out`` collects |f| per leaf copy."""
    pat = _PATTERNS.setdefault(id(clg), (clg, pattern_of(clg)))[1]
    nu, nv, nw = pat["counts"]
    groups = np.stack(np.meshgrid(np.arange(nu), np.arange(nv), np.arange(nw), indexing="ij"), -1).reshape(-1, 3)
    mats = data.get("materials", {})
    subs = {mid: (clg.materials[mid].replace, m) for mid, m in mats.items()}
    world: dict = {}

    def leaf(e, g_one):
        (key, val), = e.items()
        if key in ("union", "intersection", "difference"):
            parts = [leaf(x, g_one) for x in val]
            if key == "union":
                return np.logical_or.reduce(parts)
            if key == "intersection":
                return np.logical_and.reduce(parts)
            out = parts[0]
            for x in parts[1:]:
                out = out & ~x
            return out
        g = g_one[None]
        if key == "ball":
            c, r = node(val["node"], g[:1], pat)
            ca, ra, cb, rb = c[0], r[0] * val["scale"], None, None
            box = np.array([ca - ra, ca + ra])
        else:
            ca, ra = node(val["from"], g[:1], pat)
            cb, rb = node(val["to"], g[:1], pat)
            s1, s2 = val["scale"]
            ca, ra, cb, rb = ca[0], ra[0] * s1, cb[0], rb[0] * s2
            box = np.array([np.minimum(ca - ra, cb - rb), np.maximum(ca + ra, cb + rb)])
        if tol_out is None:  # beyond the primitive's box f > 0: only the points in it are measured
            pad = 1e-9 * (1 + np.abs(box).max())
            rows = np.flatnonzero(np.all((p >= box[0] - pad) & (p <= box[1] + pad), axis=1))
        else:
            rows = np.arange(len(p))
        f = np.linalg.norm(p[rows] - ca, axis=1) - ra if cb is None else beam_f(p[rows], ca, ra, cb, rb)
        if tol_out is not None:
            tol_out.append(np.abs(f))
        res = np.zeros(len(p), bool)
        res[rows] = f <= 0
        mid = val.get("material")
        if mid is not None and subs[mid][1].get("replace") is not None:
            sub_clg, m = subs[mid]
            if m.get("frame", "world") == "world" and tol_out is None:  # the same L for every copy
                if mid not in world:
                    world[mid] = inside(m["replace"], sub_clg, p)
                return res & world[mid]
            sel = rows if tol_out is not None else np.flatnonzero(res)  # the replacement where it matters
            o, rot, fac = frame(m.get("frame", "world"), np.repeat(ca[None], len(sel), 0), np.repeat(ra, len(sel)),
                                None if cb is None else np.repeat(cb[None], len(sel), 0))
            loc = np.einsum("mji,mj->mi", rot, p[sel] - o) / fac[:, None]
            sub_tol = [] if tol_out is not None else None
            res[sel] &= inside(m["replace"], sub_clg, loc, sub_tol)
            if tol_out is not None:
                tol_out.extend(t * fac for t in sub_tol)
        return res

    unions = {}
    for name, e in data["chunks"].items():
        ex = expand(e, pat)
        acc = np.zeros(len(p), bool)
        for g in groups:
            acc |= leaf(ex, g)
        unions[name] = acc

    def solid(e):
        if isinstance(e, str):
            return unions[e]
        (key, val), = e.items()
        parts = [solid(x) for x in val]
        if key == "union":
            return np.logical_or.reduce(parts)
        if key == "intersection":
            return np.logical_and.reduce(parts)
        out = parts[0]
        for x in parts[1:]:
            out = out & ~x
        return out
    return solid(data["solid"])
