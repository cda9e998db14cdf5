"""Hub quadrature vs analytic solids of revolution; closed-form series vs the plain sum over
hubs (1e-9); lattice area and volume vs independent Monte Carlo estimates."""

from __future__ import annotations

import math

import numpy as np
import pytest
from lattices import clean_centred_lattice
from ple.algebra.elements import beam_distance, enclosing_ball
from ple.algebra.similarity import Rotation, Scaling, Screw, Swirl, Translation
from ple.errors import PleError
from ple.measure.integrals import HalfBeam, hub_measures, hub_measures_batch, lattice_measures, lattice_volume
from ple.model.lattice import Lattice


def revolution_measures(ra, rb, length, n=400001):
    """Area and volume of the half-beam hub of one beam along x, by 1D integration of its
    radius profile: the ball up to the contact circle x = ra s, then the cone, to the cut."""
    s = (ra - rb) / length
    c = math.sqrt(1 - s * s)
    x_cut = (length**2 + ra**2 - rb**2) / (2 * length)
    x = np.linspace(-ra, x_cut, n)
    y = np.where(x < ra * s, np.sqrt(np.maximum(ra * ra - x * x, 0)), (ra - s * x) / c)
    dy = np.gradient(y, x)
    area = np.trapz(2 * math.pi * y * np.sqrt(1 + dy * dy), x)
    return area, np.trapz(math.pi * y * y, x)


@pytest.mark.parametrize("ra,rb,length", [(0.3, 0.3, 2.0), (0.3, 0.15, 2.0), (0.1, 0.25, 1.0)])
def test_hub_quadrature_matches_revolution(ra, rb, length):
    area, volume = revolution_measures(ra, rb, length)
    rng = np.random.default_rng(0)
    for _ in range(2):
        axis = rng.normal(size=3)
        axis *= length / np.linalg.norm(axis)
        a, v = hub_measures(ra, [HalfBeam(axis, ra, rb)])
        assert abs(a / area - 1) < 5e-4
        assert abs(v / volume - 1) < 5e-4


def test_two_opposite_capsules_make_a_cylinder():
    r, length = 0.2, 3.0
    a, v = hub_measures(r, [HalfBeam(np.array([0, 0, length]), r, r), HalfBeam(np.array([0, 0, -length]), r, r)])
    assert abs(v / (math.pi * r * r * length) - 1) < 5e-4
    assert abs(a / (2 * math.pi * r * length) - 1) < 5e-4


def _lattice(kind: str) -> Lattice:
    lat = Lattice()
    a = lat.add_node([1.0, 0, 0], 0.1)
    b = lat.add_node([1.4, 0.3, 0.35], 0.07)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.add_beam(a, b, 0, 0, 0)
    lat.add_beam(b, a, 1, 1, 1)
    if kind == "1":  # commuting, all similar: closed form in U, V and W (§3.7)
        lat.set_u(5, Scaling(1.15, [0, 0, 0]))
        lat.set_v(6, Rotation(0.6, [0, 0, 1], [0, 0, 0]))
        lat.set_w(5, Swirl(0.3, [0, 0, 1], [0, 0, 0], 1.1))
    elif kind == "u":  # V, W commute (rotation and screw about z): series in V and W (§3.6)
        lat.set_u(3, Translation([0.9, 0, 0.1]))
        lat.set_v(7, Rotation(0.6, [0, 0, 1], [0, 0, 0]))
        lat.set_w(6, Screw(0.2, [0, 0, 1], [0, 0, 0], 0.9))
    else:  # general: series in W only (§6.1.4)
        lat.set_u(3, Rotation(0.3, [0, 1, 0], [0, 0, 4]))
        lat.set_v(3, Screw(0.2, [0, 1, 0], [1, 0, 1], 1.0))
        lat.set_w(6, Scaling(0.93, [1, 1, 8]))
    return lat


@pytest.mark.parametrize("kind,label", [("1", "O(1)"), ("u", "O(ū)"), ("uv", "O(ūv̄)")])
def test_closed_form_equals_plain_sum(kind, label):
    lat = _lattice(kind)
    closed = lattice_measures(lat)
    plain = lattice_measures(lat, method="sum")
    assert label in closed["area_method"]
    assert plain["area_method"] == "sum over hubs"
    assert abs(closed["area"] / plain["area"] - 1) < 1e-9
    assert abs(closed["volume"] / plain["volume"] - 1) < 1e-9


def _elements(lat: Lattice):
    ev = lat.evaluate()
    a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
    return ev.center, ev.radius, ev.center[a], ev.radius[a], ev.center[b], ev.radius[b]


def _inside(p, elements, tol=0.0):
    """Is each point strictly inside (distance < -tol) some element? Also the least distance to
    the elements whose boxes hold the point (inf where none does), which is the least distance to
    all elements wherever that is <= 0. Each element measures only the points in its x-slab."""
    nc, nr, ca, ra, cb, rb = elements
    order = np.argsort(p[:, 0], kind="stable")
    x = p[order, 0]

    def near(x0: float, x1: float) -> np.ndarray:
        return order[np.searchsorted(x, x0 - 1e-9):np.searchsorted(x, x1 + 1e-9, "right")]

    d = np.full(len(p), np.inf)
    for c, r in zip(nc, nr):
        rows = near(c[0] - r, c[0] + r)
        d[rows] = np.minimum(d[rows], np.linalg.norm(p[rows] - c, axis=1) - r)
    for a, r1, b, r2 in zip(ca, ra, cb, rb):
        rows = near(min(a[0] - r1, b[0] - r2), max(a[0] + r1, b[0] + r2))
        d[rows] = np.minimum(d[rows], beam_distance(p[rows], a, r1, b, r2))
    return d < -tol, d


def test_volume_and_area_vs_monte_carlo():
    lat = clean_centred_lattice(2, Translation([0, 1, 0]))
    m = lattice_measures(lat)
    assert np.isclose(lattice_volume(lat), m["volume"])
    elements = _elements(lat)
    nc, nr, ca, ra, cb, rb = elements
    rng = np.random.default_rng(2024)
    # volume: sample each element's enclosing ball uniformly, weight 1 / (balls covering the point)
    bc, br = enclosing_ball(ca, ra, cb, rb)
    balls_c, balls_r = np.concatenate([nc, bc]), np.concatenate([nr, br])
    per = 3000
    u = rng.normal(size=(len(balls_r), per, 3))
    u *= (rng.random((len(balls_r), per, 1)) ** (1 / 3)) / np.linalg.norm(u, axis=2, keepdims=True)
    pts = (balls_c[:, None] + u * balls_r[:, None, None]).reshape(-1, 3)
    cover = np.zeros(len(pts))
    order = np.argsort(pts[:, 0], kind="stable")
    xs = pts[order, 0]
    for c, r in zip(balls_c, balls_r):  # each ball counts at the points of its x-slab
        rows = order[np.searchsorted(xs, c[0] - r - 1e-9):np.searchsorted(xs, c[0] + r + 1e-9, "right")]
        cover[rows] += np.linalg.norm(pts[rows] - c, axis=1) <= r
    inside = _inside(pts, elements)[1] <= 0
    contrib = (inside / cover).reshape(len(balls_r), per) * (4 / 3 * math.pi * balls_r[:, None] ** 3)
    v_mc = contrib.mean(axis=1).sum()
    v_err = math.sqrt((contrib.var(axis=1) / per).sum())
    assert abs(m["volume"] - v_mc) < 4 * v_err + 1e-4 * v_mc
    # area: uniform points on every sphere and cone surface, kept unless strictly inside another element
    parts, areas = [], []
    for c0, r0 in zip(nc, nr):
        g = rng.normal(size=(per, 3))
        parts.append(c0 + r0 * g / np.linalg.norm(g, axis=1, keepdims=True))
        areas.append(4 * math.pi * r0 * r0)
    for a, r1, b, r2 in zip(ca, ra, cb, rb):
        length = np.linalg.norm(b - a)
        e = (b - a) / length
        s = (r1 - r2) / length
        c = math.sqrt(1 - s * s)
        p1, p2 = r1 * c, r2 * c
        w = rng.random(per)
        t = w if abs(p2 - p1) < 1e-15 else (np.sqrt(p1 * p1 + w * (p2 * p2 - p1 * p1)) - p1) / (p2 - p1)
        x = r1 * s + t * (length + r2 * s - r1 * s)
        rho = p1 + t * (p2 - p1)
        e1 = np.cross(e, [1.0, 0, 0] if abs(e[0]) < 0.9 else [0, 1.0, 0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(e, e1)
        phi = rng.random(per) * 2 * math.pi
        parts.append(a + x[:, None] * e + rho[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2))
        areas.append(math.pi * c * c * length * (r1 + r2))
    frac = np.array([1 - _inside(p, elements, 1e-9)[0].mean() for p in parts])
    areas = np.array(areas)
    a_mc = float((frac * areas).sum())
    a_err = math.sqrt(float((areas**2 * frac * (1 - frac) / per).sum()))
    assert abs(m["area"] - a_mc) < 4 * a_err + 1e-4 * a_mc


def test_too_many_hub_classes_are_skipped_quickly():
    lat = _lattice("uv").with_counts(60, 60, 5)
    m = lattice_measures(lat, max_hubs=1000)
    assert "area" not in m and m["area_method"].startswith("skipped") and "limit 1000" in m["area_method"]


@pytest.mark.parametrize("ra,rb,length", [(0.3, 0.3, 2.0), (0.3, 0.15, 2.0), (0.1, 0.25, 1.0), (0.2, 0.6, 0.7)])
def test_fast_single_beam_hub_is_exact(ra, rb, length):
    area, volume = revolution_measures(ra, rb, length, n=2000001)
    a, v = hub_measures_batch([ra], [[[0.3 * length, -0.8 * length, math.sqrt(0.27) * length]]], [[rb]])
    assert abs(a[0] / area - 1) < 1e-6 and abs(v[0] / volume - 1) < 1e-6


def _random_hub(rng, nbeams):
    ra = 0.1
    dirs = rng.normal(size=(nbeams, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    off = dirs * rng.uniform(0.4, 1.0, (nbeams, 1))
    return ra, off, rng.uniform(0.05, 0.12, nbeams)


def test_fast_hub_matches_fine_reference_quadrature():
    rng = np.random.default_rng(7)
    for nbeams in (3, 8):
        ra, off, rb = _random_hub(rng, nbeams)
        ref_a, ref_v = hub_measures(ra, [HalfBeam(o, ra, b) for o, b in zip(off, rb)], grid=32)
        a, v = hub_measures_batch([ra], [off], [rb])
        assert abs(a[0] / ref_a - 1) < 1e-3 and abs(v[0] / ref_v - 1) < 1e-3


def test_fast_hub_converges_with_grid():
    """The adaptive result agrees with a very fine fixed grid (midpoint rule, O(h²))."""
    rng = np.random.default_rng(3)
    ra, off, rb = _random_hub(rng, 10)
    a, v = hub_measures_batch([ra], [off], [rb])
    fa, fv = hub_measures_batch([ra], [off], [rb], grid=160)
    assert abs(a[0] / fa[0] - 1) < 1e-3 and abs(v[0] / fv[0] - 1) < 1e-3


def test_shared_geometry_variants_equal_separate_hubs():
    rng = np.random.default_rng(11)
    ra, off, rb = _random_hub(rng, 6)
    masks = np.array([[1, 1, 1, 1, 1, 1], [1, 0, 1, 1, 0, 1], [0, 0, 0, 1, 0, 0]], bool)
    a, v = hub_measures_batch([ra, ra], [off, off], [rb, rb], masks[:2].repeat(1, 0)[[0, 1]], grid=12)
    av, vv = hub_measures_batch([ra], [off], [rb], masks, grid=12, geometry=[0, 0, 0])
    for m, x, y in zip(masks, av, vv):
        sa, sv = hub_measures_batch([ra], [off[m]], [rb[m]], grid=12)
        assert np.isclose(x, sa[0], rtol=1e-12) and np.isclose(y, sv[0], rtol=1e-12)
    assert np.allclose(a, av[:2], rtol=1e-12) and np.allclose(v, vv[:2], rtol=1e-12)


def test_bad_method_names_it():
    with pytest.raises(PleError, match="nope"):
        lattice_measures(_lattice("1"), method="nope")


def test_adaptive_hubs_of_a_preset_within_0_1_percent_of_a_fine_grid():
    """fig6_3 (scaling, rotation, swirl; 8 beams per hub, unequal radii): sampled boundary and
    interior hubs of its closed-form path vs a fixed 128 × 128-per-face grid."""
    from ple.measure import integrals as measure
    from ple.program.sources import load_lattice

    lat = load_lattice("fig6_3", {})
    reach = [1, 1, 1]
    segs = [measure.row_segments(c, r, s) for c, r, s in zip(lat.counts, reach, measure.similar_axes(lat))]
    idx, _, _ = measure.rep_hubs(lat, segs)
    idx = idx[np.random.default_rng(5).choice(len(idx), 16, replace=False)]
    ra, off, rb, present, _ = measure.hub_geometry(lat, idx)
    a, v = hub_measures_batch(ra, off, rb, present)
    fa, fv = hub_measures_batch(ra, off, rb, present, grid=128)
    assert np.all(np.abs(a / fa - 1) < 1e-3) and np.all(np.abs(v / fv - 1) < 1e-3)
