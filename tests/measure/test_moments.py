"""Mass properties (area, volume, centroid, inertia) against independent truths: closed forms of a
ball, a cone-beam (a solid of revolution integrated by scipy) and a cubic lattice (inclusion–
exclusion of balls, half-cylinders and Steinmetz solids), the plain sum over all hubs (1e-9), and
Monte Carlo over the (kept) elements for steady, region and filtered lattices."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from lattices import clean_centred_lattice
from ple.algebra.elements import beam_distance
from ple.algebra.similarity import Rotation, Scaling, Screw, Swirl, Translation
from ple.filters.implicit import ImplicitFilter, TPMSField
from ple.filters.lil import LiL
from ple.filters.stencil import Stencil
from ple.measure.integrals import lattice_measures
from ple.measure.moments import mass_properties
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice
from scipy.integrate import quad
from scipy.spatial.transform import Rotation as SciRot


def _matrix(props: dict, origin) -> np.ndarray:
    """∫ h hᵀ dV, h = (x − origin, 1), rebuilt from volume, centroid and second moment."""
    v = props["volume"]
    c = np.asarray(props["centroid"]) - origin
    out = np.zeros((4, 4))
    out[:3, :3] = np.asarray(props["second_moment"]) + v * np.outer(c, c)
    out[:3, 3] = out[3, :3] = v * c
    out[3, 3] = v
    return out


def _elements(ev):
    a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
    return ev.center, ev.radius, ev.center[a], ev.radius[a], ev.center[b], ev.radius[b]


def _monte_carlo(elements, n: int, seed: int):
    """Moment matrix estimate and its standard errors: uniform points in the elements' bounding box,
    h hᵀ summed over points inside some ball or cone-beam (``_inside``)."""
    nc, nr, ca, ra, cb, rb = elements
    lo = np.min(np.concatenate([nc - nr[:, None], ca - ra[:, None], cb - rb[:, None]]), axis=0)
    hi = np.max(np.concatenate([nc + nr[:, None], ca + ra[:, None], cb + rb[:, None]]), axis=0)
    origin = (lo + hi) / 2
    rng = np.random.default_rng(seed)
    box = float(np.prod(hi - lo))
    p = np.concatenate([lo + (hi - lo) * rng.random((min(20000, n - start), 3)) for start in range(0, n, 20000)])
    inside = _inside(p, elements)
    s1, s2 = np.zeros((4, 4)), np.zeros((4, 4))
    for start in range(0, n, 20000):
        rows = slice(start, start + 20000)
        h = np.concatenate([p[rows] - origin, np.ones((len(p[rows]), 1))], axis=1) * inside[rows, None]
        hh = h[:, :, None] * h[:, None, :]
        s1 += hh.sum(axis=0)
        s2 += (hh * hh).sum(axis=0)
    mean = s1 / n
    sigma = np.sqrt(np.maximum(s2 / n - mean * mean, 0) / n)
    return box * mean, box * sigma, origin


def _inside(p, elements) -> np.ndarray:
    """bool (n,): which points (n, 3) lie in some ball or cone-beam, by their exact distances. Each
    element tests only the points whose x lies within its box (sorted by x once), not all n."""
    nc, nr, ca, ra, cb, rb = elements
    order = np.argsort(p[:, 0], kind="stable")
    x = p[order, 0]
    pad = 1e-9 * (1 + np.abs(p).max())  # a point on a box's face, rounded either way, is still tested

    def near(x0: float, x1: float) -> np.ndarray:
        return order[np.searchsorted(x, x0 - pad):np.searchsorted(x, x1 + pad, "right")]

    inside = np.zeros(len(p), bool)
    for c, r in zip(nc, nr):
        rows = near(c[0] - r, c[0] + r)
        inside[rows] |= np.linalg.norm(p[rows] - c, axis=1) - r <= 0
    for a, r_a, b, r_b in zip(ca, ra, cb, rb):
        rows = near(min(a[0] - r_a, b[0] - r_b), max(a[0] + r_a, b[0] + r_b))
        inside[rows] |= beam_distance(p[rows], a, r_a, b, r_b) <= 0
    return inside


def _assert_monte_carlo(props: dict, elements, n: int = 120_000, seed: int = 7):
    est, sigma, origin = _monte_carlo(elements, n, seed)
    got = _matrix(props, origin)
    slack = 2 * props.get("quadrature_error", 0.0) / max(props["volume"], 1e-300) * np.abs(got) + 1e-12
    assert np.all(np.abs(got - est) <= 4 * sigma + slack), (got - est) / sigma


# ----- closed forms --------------------------------------------------------------------------------
def test_single_ball():
    lat = Lattice()
    lat.add_node([1.0, -2.0, 0.5], 0.7)
    m = mass_properties(lat)
    v = 4 / 3 * math.pi * 0.7**3
    assert m["volume"] == pytest.approx(v, rel=1e-12)
    assert m["area"] == pytest.approx(4 * math.pi * 0.49, rel=1e-12)
    assert np.allclose(m["centroid"], [1.0, -2.0, 0.5], atol=1e-12)
    assert np.allclose(m["inertia"], 2 / 5 * v * 0.49 * np.eye(3), rtol=1e-12, atol=1e-14)


def _hull_of_two_balls(ra, rb, length):
    """(volume, ∫x, ∫x², ∫ρ²) of hull(ball((0,0,0), ra), ball((length,0,0), rb)), by scipy quadrature
    of its profile: ball A's cap, the tangent cone, ball B's cap."""
    s = (ra - rb) / length
    xa, xb = ra * s, length + rb * s  # contact circles of the tangent cone

    def y2(x):
        if x < xa:
            return ra * ra - x * x
        if x > xb:
            return rb * rb - (x - length) ** 2
        ya, yb = math.sqrt(ra * ra - xa * xa), math.sqrt(rb * rb - (xb - length) ** 2)
        return (ya + (yb - ya) * (x - xa) / (xb - xa)) ** 2

    pts = [xa, xb]
    integ = lambda f: quad(f, -ra, length + rb, points=pts, epsabs=0, epsrel=1e-13, limit=200)[0]  # noqa: E731
    return (integ(lambda x: math.pi * y2(x)), integ(lambda x: math.pi * y2(x) * x),
            integ(lambda x: math.pi * y2(x) * x * x), integ(lambda x: math.pi * y2(x) ** 2 / 2))


@pytest.mark.parametrize("ra,rb", [(0.3, 0.3), (0.4, 0.15), (0.1, 0.35)])
def test_single_cone_beam(ra, rb):
    length = 2.0
    axis = SciRot.from_rotvec([0.3, -1.1, 0.7]).as_matrix() @ [1.0, 0, 0]
    a = np.array([0.2, 0.5, -1.0])
    lat = Lattice()
    lat.add_node(a, ra)
    lat.add_node(a + length * axis, rb)
    lat.add_beam(0, 1)
    m = mass_properties(lat)
    v, m1, m2, r2 = _hull_of_two_balls(ra, rb, length)
    assert m["volume"] == pytest.approx(v, rel=1e-10)
    assert np.allclose(m["centroid"], a + m1 / v * axis, atol=1e-10)
    ax2 = m2 - m1 * m1 / v  # about the centroid
    second = ax2 * np.outer(axis, axis) + r2 / 2 * (np.eye(3) - np.outer(axis, axis))
    inertia = np.trace(second) * np.eye(3) - second
    assert np.allclose(m["inertia"], inertia, rtol=1e-10, atol=1e-10 * np.abs(inertia).max())


def _cubic_hub(arms, r, spacing):
    """(volume, first moment (3,), ∫|x|²) about the node of ball(0, r) ∪ half-cylinders of length
    spacing/2 along ``arms`` (signed unit axes), by inclusion–exclusion: an intersection is a ball,
    a cylinder piece, a Steinmetz bicylinder or tricylinder, cut to the orthant of its arms."""
    ball = (4 / 3 * math.pi * r**3, math.pi * r**4 / 2, 4 / 5 * math.pi * r**5)  # V, ∫|x_a|, ∫|x|²
    half = spacing / 2
    bi = (16 / 3 * r**3, 3 * math.pi / 4 * r**4, 176 / 45 * r**5)
    tri = (8 * (2 - math.sqrt(2)) * r**3, (3 * math.pi / 4 - 0.5) * r**4, (176 - 92 * math.sqrt(2)) / 15 * r**5)
    sets = ["ball"] + list(arms)
    vol, first, second = 0.0, np.zeros(3), 0.0
    for size in range(1, len(sets) + 1):
        for sub in itertools.combinations(sets, size):
            a = [x for x in sub if x != "ball"]
            axes = {ax for ax, _ in a}
            if len(axes) < len(a):
                continue  # two opposite arms meet in a plane only
            sign = (-1) ** (size + 1)
            k = len(axes)
            if "ball" in sub:
                v, m, t = ball[0] / 2**k, ball[1] / 2**k, ball[2] / 2**k
            elif k == 1:
                v, t = math.pi * r * r * half, math.pi * r * r * half**3 / 3 + math.pi * r**4 / 2 * half
                m = math.pi * r * r * half**2 / 2
            else:
                base = bi if k == 2 else tri
                v, m, t = base[0] / 2**k, base[1] / 2**k, base[2] / 2**k
            vol += sign * v
            second += sign * t
            for ax, sg in a:
                first[ax] += sign * sg * m
    return vol, first, second


def test_cubic_lattice_closed_form():
    r, spacing, n = 0.2, 1.0, 4
    lat = Lattice()
    lat.add_node([0, 0, 0], r)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(0, 0, *off)
    lat.set_u(n, Translation([spacing, 0, 0]))
    lat.set_v(n, Translation([0, spacing, 0]))
    lat.set_w(n, Translation([0, 0, spacing]))
    m = mass_properties(lat)
    vol, m1, rows = 0.0, np.zeros(3), []
    for p in itertools.product(range(n), repeat=3):
        arms = [(ax, sg) for ax in range(3) for sg in (-1, 1) if 0 <= p[ax] + sg < n]
        v, f, t = _cubic_hub(arms, r, spacing)
        rows.append((np.array(p, float) * spacing, v, f, t))
        vol += v
        m1 += v * rows[-1][0] + f
    c = m1 / vol
    assert np.allclose(c, (n - 1) * spacing / 2, atol=1e-12)
    trace = sum(t + 2 * (p - c) @ f + v * (p - c) @ (p - c) for p, v, f, t in rows)
    inertia = 2 / 3 * trace * np.eye(3)  # cubic symmetry: second moment = trace / 3 · I
    tol = 3 * m["quadrature_error"] / m["volume"] + 1e-9
    assert m["volume"] == pytest.approx(vol, rel=tol)
    assert np.allclose(m["centroid"], c, atol=1e-9)
    assert np.allclose(m["inertia"], inertia, rtol=0, atol=tol * inertia[0, 0])
    assert m["closed_form"] and "O(1)" in m["method"]


# ----- steady lattices: closed-form series vs the sum over all hubs, and Monte Carlo ------------------
def _steady(kind: str) -> Lattice:
    lat = Lattice()
    a = lat.add_node([1.0, 0, 0], 0.1)
    b = lat.add_node([1.4, 0.3, 0.35], 0.07)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.add_beam(a, b, 0, 0, 0)
    lat.add_beam(b, a, 1, 1, 1)
    if kind == "1":
        lat.set_u(5, Scaling(1.15, [0, 0, 0]))
        lat.set_v(6, Rotation(0.6, [0, 0, 1], [0, 0, 0]))
        lat.set_w(5, Swirl(0.3, [0, 0, 1], [0, 0, 0], 1.1))
    elif kind == "u":
        lat.set_u(3, Translation([0.9, 0, 0.1]))
        lat.set_v(7, Rotation(0.6, [0, 0, 1], [0, 0, 0]))
        lat.set_w(6, Screw(0.2, [0, 0, 1], [0, 0, 0], 0.9))
    else:
        lat.set_u(3, Rotation(0.3, [0, 1, 0], [0, 0, 4]))
        lat.set_v(3, Screw(0.2, [0, 1, 0], [1, 0, 1], 1.0))
        lat.set_w(6, Scaling(0.93, [1, 1, 8]))
    lat.set_placement(Screw(0.4, [1, 2, 0.5], [3, -1, 2], 1.5))
    return lat


def _close(a: dict, b: dict, rel: float):
    assert a["volume"] == pytest.approx(b["volume"], rel=rel)
    assert a["area"] == pytest.approx(b["area"], rel=rel)
    scale = np.abs(np.asarray(b["inertia"])).max()
    assert np.allclose(a["centroid"], b["centroid"], rtol=0, atol=rel * np.abs(b["centroid"]).max() + 1e-12)
    assert np.allclose(a["inertia"], b["inertia"], rtol=0, atol=rel * scale)


@pytest.mark.parametrize("kind,label", [("1", "O(1)"), ("u", "O(ū)"), ("uv", "O(ūv̄)")])
@pytest.mark.parametrize("region", [None, "1:,0:3,1:5"])
def test_closed_form_equals_sum_over_hubs(kind, label, region):
    lat = _steady(kind)
    closed = mass_properties(lat, region)
    plain = mass_properties(lat, region, method="sum")
    assert label in closed["method"] and closed["closed_form"]
    assert plain["method"] == "sum over hubs" and not plain["closed_form"]
    _close(closed, plain, 1e-9)


@pytest.mark.parametrize("grid", [0, 12])
def test_volume_and_area_agree_with_lattice_measures(grid):
    """One hub routine: both APIs give the same numbers, adaptive or on a fixed grid."""
    lat = _steady("u")
    m, old = mass_properties(lat, grid=grid), lattice_measures(lat, grid=grid)
    assert m["volume"] == pytest.approx(old["volume"], rel=1e-12)
    assert m["area"] == pytest.approx(old["area"], rel=1e-12)


def test_rotated_quadrature_error_estimate_is_honest():
    """Many distinct hub geometries (bent, twisted, tapered: series along W only): the randomly
    rotated coarse grids' sums agree with a fine fixed grid within the reported error (3 σ)."""
    lat = load_lattice("thesis_warped", ["n=12"])
    m, fine = mass_properties(lat), mass_properties(lat, grid=48)
    assert m["hub_geometries"] > 100 and m["quadrature_rotations"] >= 2
    assert abs(m["volume"] - fine["volume"]) <= m["quadrature_error"] + 1e-5 * fine["volume"]
    assert abs(m["volume"] / fine["volume"] - 1) < 3e-4 and abs(m["area"] / fine["area"] - 1) < 3e-4


@pytest.mark.parametrize("region", [None, "1:3,0:2,1:3"])
def test_steady_lattice_vs_monte_carlo(region):
    lat = clean_centred_lattice(3, Rotation(0.25, [0, 0, 1], [-2, -2, 0]))
    m = mass_properties(lat, region)
    _assert_monte_carlo(m, _elements(lat.evaluate(region)))


# ----- filtered lattices ----------------------------------------------------------------------------------
def _cubic(n: int = 5, r: float = 0.18) -> Lattice:
    lat = Lattice()
    lat.add_node([0, 0, 0], r)
    lat.add_node([0.5, 0.5, 0.5], 0.7 * r)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(0, 0, *off)
    lat.add_beam(1, 0, 1, 1, 1)
    lat.add_beam(1, 0, 0, 0, 0)
    lat.set_u(n, Translation([1, 0, 0]))
    lat.set_v(n, Translation([0, 1, 0]))
    lat.set_w(n, Scaling(1.06, [0.3, 0.2, -12]))
    return lat


def _coarse() -> Lattice:
    c = Lattice()
    c.add_node([0.2, 0.1, 0.3], 0.5)
    c.add_beam(0, 0, 1, 0, 0)
    c.add_beam(0, 0, 0, 1, 0)
    c.set_u(2, Translation([3.0, 0, 0]))
    c.set_v(2, Translation([0, 3.0, 0]))
    return c


FILTERS = {
    "stencil": lambda: Stencil(np.array([[[1, 1], [0, 1]], [[1, 0], [1, 1]]])),
    "lil": lambda: LiL(_coarse()),
    "cascade": lambda: Stencil(np.array([[[1, 1, 0]]])) & LiL(_coarse()),
    "implicit": lambda: ImplicitFilter(TPMSField("gyroid", cell=3.0), level=0.3),
}


@pytest.mark.parametrize("name", sorted(FILTERS))
@pytest.mark.parametrize("region", [None, "1:5,0:4,1:5"])
def test_filtered_lattice_vs_monte_carlo(name, region):
    lat = _cubic()
    lat.set_filter(FILTERS[name]())
    ev = lat.evaluate(region)
    assert 0 < len(ev.node_index) < lat.region(region).groups * 2  # the filter removes some nodes
    m = mass_properties(lat, region)
    assert m["filtered"] and not m["closed_form"] and m["hubs"] == len(ev.node_index)
    _assert_monte_carlo(m, _elements(ev), seed=sorted(FILTERS).index(name))  # not hash(name): salted per process


@pytest.mark.parametrize("region", [None, "1:4,0:5,2:5"])
def test_filter_keeping_everything_equals_the_closed_form(region):
    lat = _cubic()
    closed = mass_properties(lat, region)
    lat.set_filter(Stencil(np.ones((1, 1, 1))))
    kept = mass_properties(lat, region)
    assert kept["method"] == "sum over kept hubs" and closed["closed_form"]
    _close(kept, closed, 1e-9)


def test_filter_removing_everything():
    lat = _cubic()
    lat.set_filter(Stencil(np.zeros((1, 1, 1))))
    m = mass_properties(lat)
    assert m["volume"] == 0 and m["area"] == 0 and m["centroid"] is None and m["hubs"] == 0


def test_cache_follows_the_lattice():
    lat = _cubic()
    first = mass_properties(lat)
    assert mass_properties(lat) == first
    lat.set_filter(Stencil(np.array([[[1, 0]]])))
    assert mass_properties(lat)["volume"] < first["volume"]
    lat.set_filter(None)
    lat.nodes[0].radius = 0.2
    assert mass_properties(lat)["volume"] > first["volume"]
