"""The conical-shell bound of a CLG (thesis §5.5, Fig. 5.5): it holds every primitive of every chunk
copy exactly (points sampled inside the primitives, node positions by explicit matrix powers in
``clg_reference``), query balls touching a primitive are never rejected, it rejects points the box
lets through, and PMC with it equals PMC without it and the brute-force CSG."""

from __future__ import annotations

import json

import numpy as np
import pytest
from clg_reference import inside, node, pattern_of
from ple.clg.bound import conical_shell
from ple.clg.ir import clg_from_dict
from ple.clg.query import Compiled, brute_force_value, compiled
from ple.program.clg_sources import load_clg
from test_clg_pmc import random_clg


def unit_ball(rng, n):
    v = rng.standard_normal((n, 3))
    return v / np.linalg.norm(v, axis=1)[:, None] * rng.random(n)[:, None] ** (1 / 3)


def primitive_points(comp, pat, rng, per_copy=6, shrink=1 - 1e-12):
    """Points inside (and on) every positive primitive of every copy of the positive chunks, with
    the balls' radii (t along a beam picks the interpolated ball c(t), r(t))."""
    out = []
    g = comp.groups()
    for c in range(len(comp.names)):
        for prim in comp.positive[c]:
            ca, ra = node((*prim.a.offset, prim.a.n), g, pat)
            ra = ra * prim.sa
            if prim.b is None:
                cc, rr = ca, ra
            else:
                cb, rb = node((*prim.b.offset, prim.b.n), g, pat)
                t = rng.random(len(g))
                cc, rr = ca + t[:, None] * (cb - ca), ra + t * (rb * prim.sb - ra)
            cc, rr = np.repeat(cc, per_copy, 0), np.repeat(rr, per_copy)
            u = unit_ball(rng, len(cc))
            u[::2] /= np.linalg.norm(u[::2], axis=1)[:, None]  # half of them on the surface
            out.append(cc + u * (rr * shrink)[:, None])
    return np.concatenate(out)


@pytest.mark.parametrize("kind, seed", [("swirl", 0), ("swirl", 1), ("becots", 2), ("becots", 3), ("becots", 4)])
def test_shell_holds_every_primitive(kind, seed):
    rng = np.random.default_rng(seed)
    data = random_clg(rng, kind)
    data["solid"] = {"union": list(data["chunks"])}  # every chunk positive: every primitive checked
    clg = clg_from_dict(data)
    comp = compiled(clg)
    assert comp.shell is not None
    pat = pattern_of(clg)
    p = primitive_points(comp, pat, rng)
    assert comp.shell.contains(p).all()
    # query balls that reach a primitive from outside are never rejected
    r = rng.uniform(0.01, 1.0, len(p))
    d = rng.standard_normal((len(p), 3))
    q = p + d / np.linalg.norm(d, axis=1)[:, None] * (r * (1 - 1e-9))[:, None]
    assert comp.shell.touches(q, r).all()


def test_no_shell_for_translations():
    rng = np.random.default_rng(5)
    assert compiled(clg_from_dict(random_clg(rng, "steady"))).shell is None


@pytest.mark.parametrize("name", ["plate", "connectors"])
def test_shell_is_tighter_than_the_box_and_pmc_unchanged(name):
    clg = load_clg(name)
    with_shell, box_only = Compiled(clg), Compiled(clg, shell=False)
    rng = np.random.default_rng(1)
    p = with_shell.lo + rng.random((4000, 3)) * (with_shell.hi - with_shell.lo)
    zero = np.zeros(len(p))
    assert len(box_only.near(p, zero)) == len(p)  # points in the box: the box lets all through
    kept = with_shell.near(p, zero)
    assert len(kept) < 0.6 * len(p)
    q_shell = len(with_shell.candidates(p[kept], zero[kept])[0])
    q_box = len(box_only.candidates(p, zero)[0])
    assert q_shell <= q_box
    got = with_shell.pmc(p)
    assert np.array_equal(got, box_only.pmc(p))
    assert np.array_equal(got[:600], brute_force_value(clg, p[:600]) <= 0)  # every copy, no bound


def test_region_shell_and_copies():
    """A region's compiled CLG holds only the region's copies: on a swirl pattern, region 0:2 of
    U equals the CLG whose U count is 2 (same PMC), and its shell holds its primitives."""
    rng = np.random.default_rng(11)
    data = random_clg(rng, "swirl")
    clg = clg_from_dict(data)
    small = json.loads(json.dumps(data))
    small["pattern"]["U"]["count"] = 2
    small_clg = clg_from_dict(small)
    region = clg.pattern.region("0:2,0:3,0:1")
    comp = compiled(clg, region)
    p = comp.lo - 0.2 + rng.random((3000, 3)) * (comp.hi - comp.lo + 0.4)
    assert np.array_equal(comp.pmc(p), inside(small, small_clg, p))
    pts = primitive_points(comp, pattern_of(clg), rng)
    assert comp.shell.contains(pts).all()
    full = compiled(clg).shell
    assert full.dist[1] >= comp.shell.dist[1]


def test_shell_of_one_ball_is_its_cap():
    """A ball of radius r at distance d from the apex: angles φ ± asin(r/d); distances from d − r
    (group 0) to (d + r) times the factor of U (group 1)."""
    lat = load_clg("plate").pattern
    shell = compiled(load_clg("plate")).shell
    c = shell.apex + 5.0 * np.array([0.6, 0.8, 0.0])
    two = lat.region("0:2,0:1,0:1")
    s = conical_shell(lat, [(c, 1.0, None, 0.0)], two)
    fu = lat.group_factors(1, 0, 0)[0] / lat.placement.factor
    phi = np.arccos(np.dot(np.array([0.6, 0.8, 0.0]), shell.axis))
    assert s.phi[0] == pytest.approx(phi - np.arcsin(0.2), abs=1e-8)
    assert s.phi[1] == pytest.approx(phi + np.arcsin(0.2), abs=1e-8)
    assert s.dist == pytest.approx((4.0 * min(1, fu), 6.0 * max(1, fu)), abs=1e-7)
