"""CHoCC (001_ §3–4): Apollonius on the sphere vs brute force, plane rolling counts, corridors
on elliptic cones, and hull volume against scipy's ConvexHull of dense circle samples (oracle)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from ple.errors import PleError
from ple.meshing.chocc import (
    apollonius_planes,
    appendix_a,
    chocc,
    cnt_segments,
    contact_points,
    corridor_apexes,
    corridor_mesh,
    map_generators,
    pair_hull_mesh,
    sampled_segments,
)
from scipy.optimize import least_squares
from scipy.spatial import ConvexHull


def random_caps(rng, n, amax=0.4, gap=0.01):
    normals, alphas = [], []
    while len(normals) < n:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        a = rng.uniform(0.0, amax)
        if all(np.arccos(np.clip(v @ w, -1, 1)) > a + b + gap for w, b in zip(normals, alphas)):
            normals.append(v)
            alphas.append(a)
    return np.array(normals), np.array(alphas)


def circle_samples(normals, alphas, k=720):
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    out = []
    for n, a in zip(normals, alphas):
        e1 = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        out.append(np.cos(a) * n + np.sin(a) * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2))
    return np.concatenate(out)


def closed_mesh(c, segments):
    m = corridor_mesh(c, segments)
    return trimesh.Trimesh(m.vertices, np.concatenate([m.faces, m.disk_faces()]), process=False), m


def brute_force_apollonius(n, a, rng, starts=200):
    """All solutions (N, alpha) of Eq. 1 with 0 < alpha < pi, by least squares from many starts."""
    def res(x):
        th, ph, al = x
        nn = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
        return nn @ n.T - np.cos(al + a)

    found = []
    for _ in range(starts):
        x0 = [rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi), rng.uniform(0.01, np.pi - 0.01)]
        r = least_squares(res, x0, xtol=1e-15, ftol=1e-15, gtol=1e-15)
        th, ph, al = r.x
        if np.max(np.abs(r.fun)) > 1e-10 or not 0 < al < np.pi:
            continue
        nn = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
        if not any(np.linalg.norm(nn - f[0]) < 1e-6 for f in found):
            found.append((nn, al))
    return found


@pytest.mark.parametrize("seed", range(4))
def test_appendix_a_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    n, a = random_caps(rng, 3)
    normals, alphas = appendix_a(n[None], a[None])
    for k in range(2):  # Eq. 1 holds for both solutions
        assert np.allclose(normals[0, k] @ n.T, np.cos(alphas[0, k] + a), atol=1e-12)
        assert abs(np.linalg.norm(normals[0, k]) - 1) < 1e-12
    truth = brute_force_apollonius(n, a, rng)
    assert len(truth) == 2
    for nn, al in truth:
        k = np.argmin(np.linalg.norm(normals[0] - nn, axis=1))
        assert np.linalg.norm(normals[0, k] - nn) < 1e-7 and abs(alphas[0, k] - al) < 1e-7


def test_paper_tangent_formula_agrees():
    """Appendix A's t = tan(alpha) = (A·B ± sqrt(...)) / (B·B − 1) gives the same planes."""
    rng = np.random.default_rng(7)
    n, a = random_caps(rng, 3)
    n1, n2, n3 = n
    det = n1 @ np.cross(n2, n3)
    A = (np.cos(a[0]) * np.cross(n2, n3) + np.cos(a[1]) * np.cross(n3, n1) + np.cos(a[2]) * np.cross(n1, n2)) / det
    B = (np.sin(a[0]) * np.cross(n2, n3) + np.sin(a[1]) * np.cross(n3, n1) + np.sin(a[2]) * np.cross(n1, n2)) / det
    ab, aa, bb = A @ B, A @ A, B @ B
    ts = [(ab + sg * np.sqrt(ab**2 - (aa - 1) * (bb - 1))) / (bb - 1) for sg in (1, -1)]
    paper = []
    for t in ts:
        for sign in (1, -1):  # the paper takes cos > 0; alpha in (90°, 180°) flips both
            c, s = sign / np.sqrt(1 + t * t), sign * t / np.sqrt(1 + t * t)
            if s > 0:
                paper.append((c * A - s * B, np.arctan2(s, c)))
    normals, alphas = appendix_a(n[None], a[None])
    for nn, al in paper:
        k = np.argmin(np.linalg.norm(normals[0] - nn, axis=1))
        assert np.allclose(normals[0, k], nn, atol=1e-10) and abs(alphas[0, k] - al) < 1e-10


def test_coplanar_normals_special_case():
    """Three cap centres on one great circle (Eq. A.3): Appendix A divides by zero; the
    null-space form still gives the two tangent planes (here z = ±cos(alpha_C))."""
    n = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0]])
    a = np.full(3, 0.3)
    normals, alphas = apollonius_planes(n[None], a[None])
    assert np.all(np.isfinite(normals))
    for k in range(2):
        assert np.allclose(normals[0, k] @ n.T, np.cos(alphas[0, k] + a), atol=1e-12)
    assert np.allclose(np.sort(normals[0, :, 2]), [-1, 1], atol=1e-12)
    assert np.allclose(alphas[0], np.pi / 2 - 0.3, atol=1e-12)


def test_contact_points_on_both_circles():
    rng = np.random.default_rng(3)
    n, a = random_caps(rng, 3)
    normals, alphas = apollonius_planes(n[None], a[None])
    p = contact_points(normals[0, :, None, :], alphas[0, :, None], n[None])  # (2, 3, 3)
    assert np.allclose(np.linalg.norm(p, axis=-1), 1)
    assert np.allclose(np.einsum("kij,ij->ki", p, n), np.cos(a), atol=1e-12)  # on C_i
    assert np.allclose(np.einsum("kij,kj->ki", p, normals[0]), np.cos(alphas[0])[:, None], atol=1e-12)  # on C


@settings(max_examples=25, deadline=None)
@given(st.integers(3, 24), st.integers(0, 10**6))
def test_counts_and_support(n, seed):
    """§3: 2n − 4 triangles, 3n − 6 corridors, 6n − 12 vertices, each triangle plane supporting."""
    normals, alphas = random_caps(np.random.default_rng(seed), n, amax=min(0.4, 2.0 / np.sqrt(n)))
    c = chocc(normals, alphas)
    cnt = c.counts()
    assert (cnt["triangles"], cnt["corridors"], cnt["vertices"], cnt["faces"]) == (2 * n - 4, 3 * n - 6,
                                                                                 6 * n - 12, 6 * n - 10)
    lim = np.minimum(c.plane_alphas[:, None] + alphas[None], np.pi)
    assert np.all(c.plane_normals @ normals.T <= np.cos(lim) + 1e-9)
    mesh, _ = closed_mesh(c, cnt_segments)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


@pytest.mark.parametrize("n", [3, 4, 7, 15, 40])
def test_hull_volume_matches_convex_hull_oracle(n):
    normals, alphas = random_caps(np.random.default_rng(n), n, amax=min(0.4, 2.0 / np.sqrt(n)))
    c = chocc(normals, alphas)
    hull = ConvexHull(circle_samples(normals, alphas)).volume
    fine, _ = closed_mesh(c, sampled_segments(256))
    crude, _ = closed_mesh(c, cnt_segments)
    assert abs(fine.volume / hull - 1) < 2e-4
    assert crude.volume <= fine.volume + 1e-12


def symmetric_cases():
    axes = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    cube = list(itertools.product([-1, 1], repeat=3))
    fcc = [v for v in itertools.product([-1, 0, 1], repeat=3) if sum(map(abs, v)) == 2]
    return [("octahedron", axes, 0.3), ("cube", cube, 0.2), ("bcc", axes + cube, 0.2), ("points", axes + cube, 0.0),
            ("fcc near-tangent", fcc, np.pi / 6 - 1e-7), ("tiny", axes, 1e-7),
            ("near-tangent equator", axes[:4] + [(0, 0, 1)], np.pi / 4 - 1e-8)]


@pytest.mark.parametrize("name,dirs,alpha", symmetric_cases(), ids=[c[0] for c in symmetric_cases()])
def test_degenerate_and_symmetric_configurations(name, dirs, alpha):
    """Ties (four circles on one plane), near-tangent caps, tiny circles and points."""
    normals = np.array(dirs, float)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    c = chocc(normals, np.full(len(normals), alpha))
    n = len(normals)
    assert c.counts()["triangles"] == 2 * n - 4
    for seg in (cnt_segments, sampled_segments(24)):
        mesh, _ = closed_mesh(c, seg)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    hull = ConvexHull(circle_samples(normals, np.full(n, alpha))).volume
    assert closed_mesh(c, sampled_segments(256))[0].volume == pytest.approx(hull, rel=1e-3)


def test_many_small_circles():
    rng = np.random.default_rng(11)
    p = rng.normal(size=(150, 3))
    c = chocc(p, np.zeros(150))
    assert c.counts()["triangles"] == 296
    mesh, _ = closed_mesh(c, cnt_segments)
    assert mesh.is_watertight and mesh.volume == pytest.approx(ConvexHull(p / np.linalg.norm(p, axis=1,
                                                                                          keepdims=True)).volume)


def test_corridor_generators_pass_through_apex():
    """§4: every generator A→A' lies on the line through the cone's apex F (Eq. 3–5), A' lies on
    C_j; equal circles give a cylinder (apex at infinity, w = 0)."""
    rng = np.random.default_rng(5)
    normals, alphas = random_caps(rng, 6)
    c = chocc(normals, alphas)
    pairs = c.corridors[:, :2]
    apex = corridor_apexes(c.normals, c.alphas, pairs)
    for (i, j), f in zip(pairs, apex):
        pts = circle_samples(normals[i:i + 1], alphas[i:i + 1], 7)
        img = map_generators(pts[None], f[None], normals[j:j + 1], alphas[j:j + 1])[0]
        assert np.allclose(np.linalg.norm(img, axis=1), 1, atol=1e-9)  # on the sphere, on plane of C_j: on C_j
        assert np.allclose(img @ normals[j], np.cos(alphas[j]), atol=1e-9)
        if abs(f[3]) > 1e-9:
            fp = f[:3] / f[3]
            assert np.allclose(np.linalg.norm(np.cross(pts - fp, img - fp), axis=1), 0, atol=1e-7)
    eq = corridor_apexes(np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.array([0.3, 0.3]), np.array([[0, 1]]))
    assert abs(eq[0, 3]) < 1e-12


def test_cnt_quads_are_planar():
    """§6: the quad approximating each corridor is planar."""
    normals, alphas = random_caps(np.random.default_rng(9), 8)
    c = chocc(normals, alphas)
    for a, b, t1, t2 in c.corridors:
        q = []
        for t, x in ((t1, a), (t2, a), (t2, b), (t1, b)):
            q.append(c.points[t, np.flatnonzero(c.triangles[t] == x)[0]])
        q = np.array(q)
        nrm = np.cross(q[1] - q[0], q[3] - q[0])
        assert abs((q[2] - q[0]) @ nrm) < 1e-10 * max(np.linalg.norm(nrm), 1e-300) + 1e-14


def test_bad_input():
    with pytest.raises(PleError, match="at least 3"):
        chocc(np.eye(3)[:2], [0.1, 0.1])
    with pytest.raises(PleError, match="overlap"):
        chocc(np.array([[1, 0, 0], [0.99, 0.1, 0], [0, 0, 1.0]]), [0.3, 0.3, 0.3])


@pytest.mark.parametrize("seed", range(3))
def test_two_circles_case(seed):
    """n = 2: two disks and one corridor band all the way round (no triangles); its volume
    converges to the ConvexHull oracle; rings run clockwise about their normals."""
    normals, alphas = random_caps(np.random.default_rng(seed), 2, amax=0.8)
    m = pair_hull_mesh(normals, alphas, 256)
    mesh = trimesh.Trimesh(m.vertices, m.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(ConvexHull(circle_samples(normals, alphas)).volume, rel=5e-4)
    for i, ring in enumerate(m.rings):
        p = m.vertices[ring]
        assert np.einsum("ij,j->", np.cross(p, np.roll(p, -1, axis=0)), normals[i]) < 0


@pytest.mark.parametrize("seed", range(3))
def test_apex_matches_eq_3_to_5(seed):
    """The homogeneous apex equals Eq. 3–5: F = L(A1, B2) ∩ L(B1, A2) with
    |FA1| = |d1 (d1 d3 + d2 d4) / (d2² − d1²)|."""
    rng = np.random.default_rng(seed)
    n, a = random_caps(rng, 2)
    a = np.array([max(a[0], a[1]) + 0.05, min(a[0], a[1])])  # unequal circles: finite apex
    f = corridor_apexes(n, a, np.array([[0, 1]]))[0]
    f = f[:3] / f[3]
    n1, n2 = n
    nn = np.cross(n1, n2)
    nn /= np.linalg.norm(nn)
    o1, o2 = np.cos(a[0]) * n1, np.cos(a[1]) * n2
    r1, r2 = np.sin(a)
    a1, b1 = o1 - r1 * np.cross(n1, nn), o1 + r1 * np.cross(n1, nn)
    a2, b2 = o2 - r2 * np.cross(n2, nn), o2 + r2 * np.cross(n2, nn)
    assert np.linalg.norm(np.cross(f - a1, b2 - a1)) < 1e-12
    assert np.linalg.norm(np.cross(f - b1, a2 - b1)) < 1e-12
    d1, d2, d3, d4 = 2 * r1, 2 * r2, np.linalg.norm(a1 - b2), np.linalg.norm(a2 - b1)
    assert np.linalg.norm(f - a1) == pytest.approx(abs(d1 * (d1 * d3 + d2 * d4) / (d2**2 - d1**2)), rel=1e-10)


def test_topology_hint_is_checked():
    """A neighbour's triangles are adopted only when they are this hull's: a good hint gives
    the rolled result, a wrong one (another configuration's) falls back to rolling."""
    rng = np.random.default_rng(21)
    normals, alphas = random_caps(rng, 9)
    rolled = chocc(normals, alphas)
    moved = chocc(normals + 1e-4 * rng.normal(size=normals.shape), alphas * (1 + 1e-4), hint=rolled.triangles)
    assert {tuple(np.roll(t, -np.argmin(t))) for t in moved.triangles} == \
        {tuple(np.roll(t, -np.argmin(t))) for t in rolled.triangles}
    other_n, other_a = random_caps(np.random.default_rng(22), 9)
    wrong = chocc(normals, alphas, hint=chocc(other_n, other_a).triangles)
    assert {tuple(np.roll(t, -np.argmin(t))) for t in wrong.triangles} == \
        {tuple(np.roll(t, -np.argmin(t))) for t in rolled.triangles}
    mesh, _ = closed_mesh(wrong, cnt_segments)
    assert mesh.is_watertight and mesh.is_winding_consistent
