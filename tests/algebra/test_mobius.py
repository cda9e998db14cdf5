"""Planar Möbius transformations (thesis §11.1–11.2) against independent computations: repeated
composition, the complex 2x2 matrix form (eigen-decomposition powers), direct inversion formulas,
points sampled on spheres."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple.algebra.mobius import Cline, Mobius, mobius_frame
from ple.algebra.similarity import Similarity
from ple.errors import PleError

coef = st.complex_numbers(min_magnitude=0.0, max_magnitude=2.0, allow_nan=False, allow_infinity=False)


def _mobius(a, b, c, d):
    while abs(a * d - b * c) < 0.05:  # keep away from degenerate coefficients
        a, d = a + 1.3, d + 0.7
    return Mobius.from_coefficients(a, b, c, d)


def _apply(m: np.ndarray, z):
    """(a z + b) / (c z + d) straight from a matrix (independent of Mobius.__call__)."""
    return (m[0, 0] * z + m[0, 1]) / (m[1, 0] * z + m[1, 1])


@settings(max_examples=60, deadline=None)
@given(coef, coef, coef, coef, st.integers(-6, 6))
def test_integer_powers_are_repeated_compositions(a, b, c, d, n):
    u = _mobius(a, b, c, d)
    raw = np.array([[u.m[0, 0], u.m[0, 1]], [u.m[1, 0], u.m[1, 1]]])
    step = raw if n >= 0 else np.linalg.inv(raw)
    rep = np.eye(2, dtype=complex)
    for _ in range(abs(n)):
        rep = rep @ step
    z = np.array([0.3 + 0.1j, -1.2 + 0.7j, 2.0 - 0.5j])
    got, want = (u ** n)(z), _apply(rep, z)
    ok = np.isfinite(want) & (np.abs(want) < 1e6)
    assert np.allclose(got[ok], want[ok], rtol=1e-7, atol=1e-7)


def test_a_near_parabolic_power_keeps_its_digits():
    """U = (i z + 8e-27) / (-1.866 z + i) is parabolic to 1e-26: its fixed points' conjugation
    lost four digits (hypothesis found it); integer powers are U's own products."""
    u = _mobius(1j, 8.050016044641517e-27, -1.866042081612517, 1j)
    assert u.near_parabolic()
    raw = np.array([[u.m[0, 0], u.m[0, 1]], [u.m[1, 0], u.m[1, 1]]])
    z = np.array([0.3 + 0.1j, -1.2 + 0.7j, 2.0 - 0.5j])
    for n in (-3, 1, 2, 5):
        rep = np.linalg.matrix_power(raw if n >= 0 else np.linalg.inv(raw), abs(n))
        assert np.allclose((u ** n)(z), _apply(rep, z), rtol=1e-12, atol=1e-12)


def _eigen_power(u: Mobius, t: float) -> np.ndarray:
    """U**t from the matrix form: P diag(λ1^t, λ2^t) P⁻¹ with principal branches."""
    w, p = np.linalg.eig(u.m)
    return p @ np.diag(w**t) @ np.linalg.inv(p)


@pytest.mark.parametrize("t", [0.5, 0.25, -0.7, 1.5, 2.0 / 3.0])
def test_real_powers_match_the_complex_matrix_form(t):
    # loxodromic, elliptic and hyperbolic transformations with small multiplier angles
    cases = [Mobius.from_coefficients(1 + 0.2j, 0.3, 0.1 - 0.05j, 1.1),
             Mobius.from_coefficients(np.exp(0.4j), 0.5, 0.2j, np.exp(-0.4j)),
             Mobius.from_coefficients(2.0, 1.0, 1.0, 1.0)]
    z = np.array([0.2 + 0.3j, 1.5 - 0.4j, -0.8 + 0.9j])
    for u in cases:
        assert np.allclose((u ** t)(z), _apply(_eigen_power(u, t), z), atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(coef, coef, coef, coef, st.floats(-2, 2), st.floats(-2, 2))
def test_powers_add(a, b, c, d, s, t):
    u = _mobius(a, b, c, d)
    lhs = (u ** s) @ (u ** t)
    z = np.array([0.4 + 0.2j, -0.3 - 0.6j])
    want = (u ** (s + t))(z)
    ok = np.abs(want) < 1e5
    assert np.allclose(lhs(z)[ok], want[ok], rtol=1e-6, atol=1e-6)


def test_parabolic_and_similarity_powers():
    par = Mobius.from_coefficients(1, 0, 0.5, 1)  # one fixed point (0)
    assert (par ** 0.5 @ par ** 0.5).allclose(par)
    assert (par ** 3).allclose(par @ par @ par)
    sim = Mobius.from_similarity(Similarity.from_point_pairs((0, 0), (1, 0), (1, 1), (1.5, 2)))
    assert sim.is_similarity
    assert (sim ** 0.5 @ sim ** 0.5).allclose(sim)


def test_frame_form_round_trip_and_eq_11_3():
    a, b, c = 0.1 + 0.2j, 1.3 - 0.1j, 0.2 + 1.4j
    g = Mobius.from_frame(a, b, c)
    assert np.allclose(g.frame(), (a, b, c))
    # an independent frame->transformation: solve the 3 linear equations a z + b - w c z - w d = 0
    src, dst = np.array([0, 1, 1j]), np.array([a, b, c])
    mat = np.stack([src, np.ones(3), -dst * src, -dst], axis=1)
    coeffs = np.linalg.svd(mat)[2][-1].conj()
    z = np.array([0.5 + 0.5j, -2 + 1j])
    assert np.allclose(g(z), _apply(coeffs.reshape(2, 2), z))
    h = Mobius.between_frames((a, b, c), (0, 1, 1j))
    assert (h @ g).allclose(Mobius.identity())


def test_fixed_points_are_fixed_and_inverse():
    u = Mobius.from_coefficients(1 + 0.2j, 0.3, 0.1 - 0.05j, 1.1)
    f1, f2 = u.fixed_points()
    assert np.allclose(u(np.array([f1, f2])), [f1, f2])
    assert (u @ u.inverse()).allclose(Mobius.identity())
    assert abs(u(np.array([-u.coefficients[3] / u.coefficients[2]]))[0]) > 1e10  # the pole goes to ∞


def test_cline_inversions():
    circ = Cline.circle(0.2 + 0.1j, 1.3)
    z = np.array([0.7 + 0.4j, -1 + 2j, 3 - 1j])
    w = circ.invert(z)
    # on the ray from the centre, |z - O| |w - O| = r^2
    assert np.allclose(np.abs(z - circ.center) * np.abs(w - circ.center), 1.3**2)
    assert np.allclose(np.angle(z - circ.center), np.angle(w - circ.center))
    assert np.allclose(circ.invert(w), z)
    line = Cline.through(0, 1 + 1j)
    assert np.allclose(line.invert(np.array([1 + 0j])), [1j])  # reflection across y = x
    # two inversions compose to a Möbius transformation (§11.1.1)
    other = Cline.circle(-1, 0.7)
    assert np.allclose((circ @ other)(z), circ.invert(other.invert(z)))
    assert np.allclose((line @ other)(z), line.invert(other.invert(z)))
    # a Möbius steady pattern is a similarity pattern under an inversion at a fixed point (§11.2.1)
    u = Mobius.from_coefficients(1 + 0.2j, 0.3, 0.1 - 0.05j, 1.1)
    r = Cline.circle(u.fixed_points()[0], 2.0)
    s = r @ Cline.circle(0, 1)  # any Möbius; conjugate U:
    f = u.fixed_points()[0]
    conj = Mobius.conjugated(u.similarity_part()[0], Cline.circle(f, np.sqrt(abs(f) ** 2 + 1)))
    assert conj.allclose(u)
    assert s is not None


def test_mobius_frame_interpolation_eq_11_5():
    f0 = (0j, 1 + 0j, 1j)
    f1 = (2 + 0.5j, 2.8 + 1.1j, 1.5 + 1.2j)
    g = Mobius.between_frames(f0, f1)
    assert np.allclose(mobius_frame(f0, f1, 1.0), f1)
    assert np.allclose(mobius_frame(f0, f1, 3), (g @ g @ g)(np.array(f0)))
    half = mobius_frame(f0, f1, 0.5)
    assert np.allclose(mobius_frame(half, f1, 1.0), f1)  # G^(1/2) twice is G
    assert np.allclose(Mobius.between_frames(f0, half)(np.array(half)), f1)


def test_balls_map_to_balls_poincare_extension():
    rng = np.random.default_rng(3)
    u = Mobius.from_coefficients(1 + 0.2j, 0.3, 0.4 - 0.25j, 1.1)
    c = np.array([[0.3, 0.2, 0.1], [1, 1, 0], [2, -1, 0.5]])
    r = np.array([0.1, 0.2, 0.3])
    cc, rr = u.map_balls(c, r)
    for q in range(3):
        d = rng.normal(size=(200, 3))
        d /= np.linalg.norm(d, axis=1)[:, None]
        p = u.apply_points(c[q] + r[q] * d)
        assert np.allclose(np.linalg.norm(p - cc[q], axis=1), rr[q], atol=1e-12)
    # the plane z = 0 maps by the complex form
    p = u.apply_points(np.array([[0.3, 0.2, 0.0]]))[0]
    assert np.allclose(p[:2], [u(0.3 + 0.2j).real, u(0.3 + 0.2j).imag]) and p[2] == 0
    pole = -u.coefficients[3] / u.coefficients[2]
    with pytest.raises(PleError, match="pole"):
        u.map_balls(np.array([[pole.real, pole.imag, 0.0]]), np.array([0.1]))


def test_degenerate_inputs_are_named():
    with pytest.raises(PleError, match="ad - bc"):
        Mobius.from_coefficients(1, 2, 2, 4)
    with pytest.raises(PleError, match="distinct"):
        Mobius.from_frame(0, 0, 1j)


def test_powers_stay_accurate_near_parabolic_with_far_fixed_points():
    """c tiny and a ≈ d: both fixed points far away; the conjugating inversion must stay well
    conditioned (found by fuzzing: a unit-radius inversion lost 6+ digits here)."""
    rng = np.random.default_rng(7)
    z = np.array([0.3 + 0.2j, -0.5 + 0.1j])
    worst = 0.0
    for n in range(600):
        a, b, c, d = rng.normal(size=4) + 1j * rng.normal(size=4)
        c *= 10.0 ** -rng.uniform(0, 8)
        if n % 2:
            d = a + 10.0 ** -rng.uniform(4, 9)
        u = Mobius.from_coefficients(a, b, c, d)
        h, cube = u ** 0.5, u @ u @ u
        for got, want in (((h @ h)(z), u(z)), ((u ** 3)(z), cube(z))):
            worst = max(worst, float(np.abs(got - want).max() / max(1.0, np.abs(want).max())))
    assert worst < 1e-8
