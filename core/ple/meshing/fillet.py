"""Junction fillets (CHoCC paper 001_ §6, Eq. 6): the refined hub mesh projected onto a blend.

Near one ball the filleted lattice is ``{d(P) <= 0}`` with Blinn's blobby blend

    d(P) = -ln Σ_i exp(-b d_i(P)) / b                                      (Eq. 6)

over the ball's incident beams, d_i the signed distance to beam i in union with its two balls
(``elements.beam_distance``). The refined style's central projection then moves each new
vertex along its ray from the ball's centre onto ``d = 0`` instead of onto the lattice (§6,
Fig. 19 right), by sphere tracing from the lattice's own exit (the blend is 1-Lipschitz and
below every d_i, so the fillet surface lies outside the lattice and no step overshoots it).
Vertices on the contact rings stay where the beams' strips meet them: the mesh stays closed.

The blend reaches beyond the lattice's own junction: along each beam it stands out until the
other beams are a few 1/b away. So a filleted hub gets its own, larger S⁺ (``reach``): the
smallest r⁺ at which the blend lies within ``REACH_TOL`` ball radii of the beams on every
contact circle. Beyond it the beams' strips are the blend to that tolerance, and the mesh holds
the blend's whole volume gain (capped where the disks would leave the first part of a beam).

The fillet is sized relative to the ball: ``size`` s puts the blend s·r outward at a
symmetric crease between two beams (there d = x - ln 2 / b), so b = ln 2 / (s r).
"""

from __future__ import annotations

import math

import numpy as np

from ..algebra.elements import beam_distance
from ..algebra.vectors import perpendicular_frames
from ..errors import PleError, echo
from .achocc import HubGeometry, contact_circles, hub_geometry

MAX_STEPS = 400
TOL = 1e-10  # of the ball radius
REACH_TOL = 1e-2  # of the ball radius: the blend's height over the beams at the contact circles
REACH_STEP = 1.03  # r⁺ grows by this factor until the blend has settled onto the beams
RING_SAMPLES = 32


def blobbiness(size: float, radius: float) -> float:
    """b of Eq. 6 for a fillet of ``size`` ball radii."""
    size = float(size)
    if not (math.isfinite(size) and size > 0):
        raise PleError(f"fillet size must be a positive fraction of the ball radius, got {echo(size)}")
    return math.log(2.0) / (size * radius)


class FilletedHub:
    """A HubGeometry whose ``exit_distance`` reaches the fillet surface (Eq. 6)."""

    def __init__(self, hub: HubGeometry, size: float):
        self.hub, self.size = hub, float(size)
        self.b = blobbiness(size, hub.radius)

    def __getattr__(self, name):  # everything else is the hub's
        return getattr(self.hub, name)

    def blend(self, p: np.ndarray) -> np.ndarray:
        """d(P) of Eq. 6 at points (V, 3) in hub coordinates (centre at 0)."""
        h = self.hub
        p = np.asarray(p, float).reshape(-1, 3)
        if not len(h.dirs):
            return np.linalg.norm(p, axis=1) - h.radius
        d = np.stack([beam_distance(p, np.zeros(3), h.radius, h.dirs[k] * h.lengths[k], h.other_radii[k])
                      for k in range(len(h.dirs))], axis=1)
        m = d.min(axis=1)  # log-sum-exp, shifted for range
        return m - np.log(np.exp(-self.b * (d - m[:, None])).sum(axis=1)) / self.b

    def exit_distance(self, u: np.ndarray) -> np.ndarray:
        """Distance (V,) from the centre along unit rays u (V, 3) to the fillet surface."""
        u = np.asarray(u, float).reshape(-1, 3)
        t = self.hub.exit_distance(u)  # on the lattice: d <= 0 there
        tol = TOL * self.hub.radius
        active = np.ones(len(u), bool)
        for _ in range(MAX_STEPS):
            if not active.any():
                break
            d = self.blend(t[active, None] * u[active])
            step = np.maximum(-d, 0.0)
            t[active] += step
            done = step <= tol
            idx = np.flatnonzero(active)
            active[idx[done]] = False
        return t


def reach(hub: HubGeometry, size: float) -> float:
    """The r⁺ (hub units) beyond which the blend of Eq. 6 stands at most REACH_TOL ball radii
    over the beams: sampled on each beam's contact circle, grown from the hub's own r⁺."""
    fh = FilletedHub(hub, size)
    s = len(hub.dirs)
    if s < 2:
        return hub.r_plus
    e1, e2 = perpendicular_frames(hub.dirs)
    ang = np.arange(RING_SAMPLES) * 2 * np.pi / RING_SAMPLES
    ring = np.cos(ang)[:, None, None] * e1[None] + np.sin(ang)[:, None, None] * e2[None]  # (m, S, 3)
    r_plus = hub.r_plus
    for _ in range(MAX_STEPS):
        _, x, y = contact_circles(hub.radius, r_plus, hub.dirs, hub.other_radii, hub.lengths, strict=False)
        pts = (x[:, None] * hub.dirs)[None] + y[None, :, None] * ring
        if np.abs(fh.blend(pts.reshape(-1, 3))).max() <= REACH_TOL * hub.radius:
            break
        r_plus *= REACH_STEP
        if np.any(x >= 0.5 * hub.lengths):  # the disks would pass the beams' middles
            break
    return r_plus


def filleted(hub: HubGeometry, size: float | None, hint=None):
    """The hub with a fillet of ``size`` ball radii (None or 0: the hub itself), rebuilt on the
    S⁺ that holds the blend (``reach``)."""
    if not size:
        return hub
    grown = hub_geometry(hub.radius, hub.dirs, hub.other_radii, hub.lengths, hint, reach(hub, size))
    return FilletedHub(grown, size)
