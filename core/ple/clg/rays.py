"""Ray queries on a CLG (thesis §5.7, §10.3): sphere tracing with local distance bounds and
closed-form ray hits of balls and cone-beams, and a shaded, progressive render.

Each step asks the CLG for its clipped CSG value in a query ball of radius R about the current
point Q (only the chunk copies near Q are visited) and, for every primitive in that ball, the
distance along the ray to its next boundary crossing, in closed form (a ball: a quadratic; a
cone-beam: its two balls and the frustum between the tangent circles, a quadric within a slab).
The solid's membership can change only where some primitive's does, so the ray may safely
advance by the larger of the sphere-tracing bound and the nearest crossing (never beyond R).
R adapts per ray: it doubles in empty space and shrinks near surfaces.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PleError

MAX_STEPS = 4000


def ray_ball_interval(o, d, c, r):
    """(t0, t1) where the rays o + t d (|d| = 1) are inside balls (c, r); nan when they miss."""
    oc = o - c
    b = np.sum(oc * d, axis=-1)
    cc = np.sum(oc * oc, axis=-1) - r * r
    disc = b * b - cc
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    return -b - root, -b + root


def ray_beam_interval(o, d, ca, ra, cb, rb):
    """(t0, t1) where the rays are inside cone-beams hull(ball(ca, ra), ball(cb, rb)); nan: a miss.

    The hull is ball a ∪ ball b ∪ the frustum between the tangent circles (axial coordinate from
    x_a = ra s to x_b = L + rb s, radius (ra − s x)/c there); a convex set, so its interval is
    [min of entries, max of exits] of the parts."""
    a0, a1 = ray_ball_interval(o, d, ca, ra)
    b0, b1 = ray_ball_interval(o, d, cb, rb)
    ab = cb - ca
    length = np.linalg.norm(ab, axis=-1)
    safe = np.where(length > 0, length, 1.0)
    e = ab / safe[..., None]
    s = (ra - rb) / safe
    valid = (length > 0) & (np.abs(s) < 1)
    s = np.where(valid, s, 0.0)
    c2 = 1 - s * s
    w = o - ca
    xo, xd = np.sum(w * e, axis=-1), np.sum(d * e, axis=-1)
    # |perp|² = |w + t d|² − (xo + t xd)²
    pa = 1 - xd * xd
    pb = 2 * (np.sum(w * d, axis=-1) - xo * xd)
    pc = np.sum(w * w, axis=-1) - xo * xo
    # q(t) = c² |perp|² − (ra − s x)² ≤ 0
    k0, k1 = ra - s * xo, -s * xd
    qa, qb, qc = c2 * pa - k1 * k1, c2 * pb - 2 * k0 * k1, c2 * pc - k0 * k0
    xa, xb = ra * s, length + rb * s
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (xa - xo) / xd, (xb - xo) / xd
        s0 = np.where(np.abs(xd) > 1e-300, np.minimum(ta, tb), np.where((xo >= xa) & (xo <= xb), -np.inf, np.inf))
        s1 = np.where(np.abs(xd) > 1e-300, np.maximum(ta, tb), np.where((xo >= xa) & (xo <= xb), np.inf, -np.inf))
        disc = qb * qb - 4 * qa * qc
        sq = np.sqrt(np.maximum(disc, 0))
        big = np.abs(qa) > 1e-12 * (np.abs(qb) + np.abs(qc) + 1e-300)
        r1 = np.where(big, (-qb - np.sign(qa) * sq) / (2 * qa), np.nan)
        r2 = np.where(big, (-qb + np.sign(qa) * sq) / (2 * qa), np.nan)
        lo_r, hi_r = np.minimum(r1, r2), np.maximum(r1, r2)
        # the solution set of q ≤ 0 as up to two intervals [u0, u1] ∪ [v0, v1]
        lin = -qc / qb  # qa ≈ 0: qb t + qc ≤ 0
        u0 = np.where(big, np.where(qa > 0, np.where(disc >= 0, lo_r, np.inf), np.where(disc >= 0, -np.inf, -np.inf)),
                      np.where(qb > 0, -np.inf, np.where(qb < 0, lin, np.where(qc <= 0, -np.inf, np.inf))))
        u1 = np.where(big, np.where(qa > 0, np.where(disc >= 0, hi_r, -np.inf), np.where(disc >= 0, lo_r, np.inf)),
                      np.where(qb > 0, lin, np.where(qb < 0, np.inf, np.where(qc <= 0, np.inf, -np.inf))))
        v0 = np.where(big & (qa < 0) & (disc >= 0), hi_r, np.inf)
        v1 = np.where(big & (qa < 0) & (disc >= 0), np.inf, -np.inf)
    f0 = np.full_like(xo, np.nan)
    f1 = np.full_like(xo, np.nan)
    for p0, p1 in ((u0, u1), (v0, v1)):
        lo, hi = np.maximum(p0, s0), np.minimum(p1, s1)
        ok = valid & (lo <= hi)
        f0 = np.where(ok, np.fmin(f0, lo), f0)
        f1 = np.where(ok, np.fmax(f1, hi), f1)
    t0 = np.fmin(np.fmin(a0, b0), f0)
    t1 = np.fmax(np.fmax(a1, b1), f1)
    return t0, t1


def next_crossing(t0, t1, tiny) -> np.ndarray:
    """Distance to the next boundary crossing after ``tiny`` (inf when none)."""
    out = np.where(t0 > tiny, t0, np.where(t1 > tiny, t1, np.inf))
    return np.where(np.isnan(out), np.inf, out)


def box_interval(o, d, lo, hi):
    """(t0, t1) of rays inside an axis-aligned box (t0 > t1: a miss)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        a, b = (lo - o) * inv, (hi - o) * inv
    a = np.where(np.isnan(a), -np.inf, a)
    b = np.where(np.isnan(b), np.inf, b)
    return np.max(np.minimum(a, b), axis=1), np.min(np.maximum(a, b), axis=1)


def trace(comp, origins, dirs, max_steps: int = MAX_STEPS, progress=None):
    """First-hit distances (q,) of rays (origins, unit dirs) against a compiled CLG (inf: a miss)."""
    o = np.asarray(origins, float).reshape(-1, 3)
    d = np.asarray(dirs, float).reshape(-1, 3)
    n = np.linalg.norm(d, axis=1)
    if not np.all(np.isfinite(o)) or not np.all(np.isfinite(d)) or np.any(np.abs(n - 1) > 1e-6):
        raise PleError("rays: origins must be finite and directions unit vectors")
    d = d / n[:, None]
    scale = max(comp.scale, 1e-12)
    tiny = 1e-10 * scale
    eps = 1e-9 * scale
    pad = 1e-6 * scale
    b0, b1 = box_interval(o, d, comp.lo - pad, comp.hi + pad)
    t = np.maximum(b0, 0.0)
    out = np.full(len(o), np.inf)
    active = np.nonzero(b0 <= b1)[0]
    rad = np.full(len(o), comp.step_radius)
    steps = 0
    while len(active) and steps < max_steps:
        steps += 1
        q = o[active] + t[active, None] * d[active]
        v, ev = comp.value_event(q, rad[active], d[active], tiny)
        hit = v <= eps
        out[active[hit]] = t[active[hit]]
        step = np.maximum(np.where(v > 0, v, 0.0), np.minimum(rad[active], ev))
        step = np.maximum(step, tiny)
        t[active] += step
        grow = np.where(step >= rad[active] * 0.999, 2 * rad[active], np.maximum(2 * step, rad[active] * 0.5))
        rad[active] = np.clip(grow, comp.step_radius * 1e-3, comp.step_radius * 4)
        gone = hit | (t[active] > b1[active])
        if progress is not None:
            progress(int(gone.sum()))
        active = active[~gone]
    if len(active):
        raise PleError(f"rays: {len(active)} rays did not converge in {max_steps} steps")
    return out


# ----- pictures ---------------------------------------------------------------------------------------
def camera_rays(comp, size, view=(35.0, 25.0), fov: float = 35.0):
    """Origins and unit directions (h, w, 3) of a perspective camera looking at the solid's box
    from azimuth/elevation ``view`` (degrees), framed to fit the box."""
    w, h = size
    lo, hi = comp.lo, comp.hi
    centre = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    az, el = (math.radians(x) for x in view)
    back = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    dist = radius / math.sin(math.radians(fov) / 2) * 1.05
    eye = centre + back * dist
    fwd = -back
    right = np.cross(fwd, [0, 0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.array([1.0, 0, 0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    tan = math.tan(math.radians(fov) / 2)
    aspect = w / h
    xs = (2 * (np.arange(w) + 0.5) / w - 1) * tan * aspect
    ys = (1 - 2 * (np.arange(h) + 0.5) / h) * tan
    dirs = fwd + xs[None, :, None] * right + ys[:, None, None] * up
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return np.broadcast_to(eye, dirs.shape).copy(), dirs


def shade(comp, points, dirs) -> np.ndarray:
    """Lambert + ambient grey levels in [0, 1] from normals by central differences of the value."""
    h = 1e-5 * comp.scale
    r = np.full(len(points), 10 * h)
    grad = np.zeros_like(points)
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        grad[:, k] = comp.value(points + e, r) - comp.value(points - e, r)
    nrm = grad / np.maximum(np.linalg.norm(grad, axis=1, keepdims=True), 1e-300)
    light = np.array([0.4, 0.3, 0.85])
    light /= np.linalg.norm(light)
    lam = np.abs(nrm @ light)
    facing = np.abs(np.sum(nrm * dirs, axis=1))
    return np.clip(0.15 + 0.65 * lam + 0.2 * facing, 0, 1)


def render(comp, size=(640, 480), view=(35.0, 25.0), passes: int = 4, progress=None, on_pass=None):
    """A shaded picture (h, w) uint8, progressive: pass k traces every 2^(passes−1−k)-th pixel not
    yet traced and fills the rest from the nearest traced one; ``on_pass(k, image)`` sees each."""
    w, h = size
    if w < 1 or h < 1 or w * h > 1 << 24:
        raise PleError(f"render size {w}x{h}: expected 1..16M pixels")
    o, d = camera_rays(comp, size, view)
    img = np.zeros((h, w))
    done = np.zeros((h, w), bool)
    for k in range(passes):
        stride = 2 ** (passes - 1 - k)
        mask = np.zeros((h, w), bool)
        mask[::stride, ::stride] = True
        mask &= ~done
        ys, xs = np.nonzero(mask)
        oo, dd = o[ys, xs], d[ys, xs]
        t = trace(comp, oo, dd, progress=progress)
        val = np.full(len(t), 1.0)  # background: white
        hit = np.isfinite(t)
        if hit.any():
            val[hit] = shade(comp, oo[hit] + t[hit, None] * dd[hit], dd[hit])
        img[ys, xs] = val
        done |= mask
        sy = (np.arange(h) // stride) * stride
        sx = (np.arange(w) // stride) * stride
        shown = np.where(done, img, img[sy][:, sx])
        if on_pass is not None:
            on_pass(k, (shown * 255).astype(np.uint8))
    return (img * 255).astype(np.uint8)
