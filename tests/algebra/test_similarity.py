"""Laws of the similarity algebra (thesis §2.4–2.5) against independent matrix computations."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import reference_matrix, similarities
from hypothesis import given, settings
from hypothesis import strategies as st
from ple import PleError, Pt, Rotation, Scaling, Screw, Similarity, Swirl, Translation, Vec
from ple.algebra.similarity import similarity_from_dict


def close(a, b, tol=1e-9):
    a, b = np.asarray(a), np.asarray(b)
    return np.abs(a - b).max() <= tol * max(1.0, np.abs(a).max(), np.abs(b).max())


@settings(max_examples=150, deadline=None)
@given(similarities())
def test_canonical_matrix_matches_independent_composition(ks):
    kind, params = ks
    s = similarity_from_dict({"kind": kind, **params})
    assert s.kind == kind
    assert close(s.matrix, reference_matrix(kind, **params))


@settings(max_examples=150, deadline=None)
@given(similarities(), st.floats(-2.5, 2.5), st.floats(-2.5, 2.5))
def test_power_addition_law(ks, a, b):
    s = similarity_from_dict({"kind": ks[0], **ks[1]})
    assert close(((s ** a) @ (s ** b)).matrix, (s ** (a + b)).matrix, 1e-8)


@settings(max_examples=100, deadline=None)
@given(similarities(), st.integers(1, 9))
def test_root_then_power_is_identity(ks, n):
    s = similarity_from_dict({"kind": ks[0], **ks[1]})
    assert close(np.linalg.matrix_power((s ** (1.0 / n)).matrix, n), s.matrix, 1e-8)


@settings(max_examples=100, deadline=None)
@given(similarities(), st.integers(-6, 12))
def test_integer_powers_equal_matrix_powers(ks, n):
    s = similarity_from_dict({"kind": ks[0], **ks[1]})
    ref = np.linalg.matrix_power(reference_matrix(ks[0], **ks[1]), abs(n))
    if n < 0:
        ref = np.linalg.inv(ref)
    assert close((s ** n).matrix, ref, 1e-8)
    assert close(s.power_matrices([n])[0], ref, 1e-8)


@settings(max_examples=150, deadline=None)
@given(similarities())
def test_matrix_canonical_round_trip(ks):
    s = similarity_from_dict({"kind": ks[0], **ks[1]})
    back = Similarity.from_matrix(s.matrix)
    assert close(back.matrix, s.matrix)
    assert back.kind == s.kind
    # the canonical form is fixed: again from its own matrix gives the same parameters
    again = Similarity.from_matrix(back.matrix)
    assert close(np.r_[again.factor, again.angle, again.axis, again.point, again.distance],
                 np.r_[back.factor, back.angle, back.axis, back.point, back.distance], 1e-7)


@settings(max_examples=100, deadline=None)
@given(similarities())
def test_inverse(ks):
    s = similarity_from_dict({"kind": ks[0], **ks[1]})
    assert close((s @ s.inverse()).matrix, np.eye(4), 1e-9)


def test_angles_beyond_two_pi_are_kept_when_canonical():
    s = Rotation(3 * math.pi, Vec(0, 0, 1), Pt(1, 0, 0))
    half = s ** 0.5  # 1.5 π, not the 0.5 π a matrix square root would give
    assert half.angle == pytest.approx(1.5 * math.pi)
    assert close(half.apply_points([2, 0, 0]), [1, -1, 0])


def test_apply_balls_scales_radius():
    s = Swirl(0.3, Vec(0, 1, 0), Pt(1, 2, 3), 2.0)
    c, r = s.apply_balls(np.array([[1.0, 0, 0]]), np.array([0.5]))
    assert r[0] == pytest.approx(1.0)
    assert close(c[0], (reference_matrix("swirl", angle=0.3, axis=[0, 1, 0], point=[1, 2, 3], factor=2.0)
                        @ [1, 0, 0, 1])[:3])
    assert close(s.apply_vectors([1.0, 0, 0]), 2.0 * np.array([math.cos(0.3), 0, -math.sin(0.3)]))


@pytest.mark.parametrize("m, kind", [
    (np.eye(4), "identity"),
    (Translation(Vec(1, 2, 3)).matrix, "translation"),
    (Rotation(0.7, Vec(1, 1, 1), Pt(1, 0, 0)).matrix, "rotation"),
    (Scaling(2.0, Pt(1, 1, 1)).matrix, "scaling"),
    (Screw(1.1, Vec(0, 0, 1), Pt(2, 0, 0), 0.5).matrix, "screw"),
    (Swirl(1.1, Vec(0, 1, 0), Pt(2, 0, 0), 0.5).matrix, "swirl"),
    (Rotation(math.pi, Vec(0, 1, 0), Pt(1, 0, 3)).matrix, "rotation"),  # half turn: axis from R + I
])
def test_special_cases_are_named(m, kind):
    s = Similarity.from_matrix(m)
    assert s.kind == kind
    assert close(s.matrix, m)


def test_near_degenerate_axis_becomes_translation():
    # a rotation of 1e-13 rad: the axis is meaningless, the map is a translation to 1e-12
    m = Screw(1e-13, Vec(0, 0, 1), Pt(0, 0, 0), 1.0).matrix
    m[:3, 3] += [0.3, 0, 0]
    s = Similarity.from_matrix(m)
    assert s.kind == "translation"
    assert close(s.matrix, m, 1e-12)


def test_half_turn_screw_decomposes():
    m = Screw(math.pi, Vec(1, 2, 2), Pt(1, -1, 0.5), 0.3).matrix
    s = Similarity.from_matrix(m)
    assert s.kind == "screw" and close(s.matrix, m)


def test_between_frames_maps_frame_a_onto_b(rng):
    for _ in range(50):
        a = Similarity.from_matrix(_random_similarity_matrix(rng))
        b = Similarity.from_matrix(_random_similarity_matrix(rng))
        fa = (a.apply_points([0, 0, 0]), a.apply_vectors([1, 0, 0]), a.apply_vectors([0, 1, 0]),
              a.apply_vectors([0, 0, 1]))
        fb = (b.apply_points([0, 0, 0]), b.apply_vectors([1, 0, 0]), b.apply_vectors([0, 1, 0]),
              b.apply_vectors([0, 0, 1]))
        s = Similarity.between_frames(fa, fb)
        assert close(s.apply_points(fa[0]), fb[0])
        for va, vb in zip(fa[1:], fb[1:]):
            assert close(s.apply_vectors(va), vb)
            # a frame's tip O + X goes to the other frame's tip
            assert close(s.apply_points(fa[0] + va), fb[0] + vb)


def _random_similarity_matrix(rng) -> np.ndarray:
    m = np.eye(4)
    q = rng.normal(size=4)
    m[:3, :3] = rng.uniform(0.3, 3) * SciRotation.from_quat(q / np.linalg.norm(q)).as_matrix()
    m[:3, 3] = rng.normal(size=3) * 3
    return m


from scipy.spatial.transform import Rotation as SciRotation  # noqa: E402


def test_between_frames_rejects_bad_frames():
    good = (np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]))
    with pytest.raises(PleError, match="orthogonal"):
        Similarity.between_frames(good, (np.zeros(3), np.array([1.0, 0, 0]), np.array([1.0, 1, 0]),
                                         np.array([0, 0, 1.0])))
    with pytest.raises(PleError, match="right-handed"):
        Similarity.between_frames(good, (np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                                         np.array([0, 0, -1.0])))


def test_planar_point_pairs_against_thesis_construction(rng):
    for _ in range(100):
        a, b, c, d = rng.normal(size=(4, 2)) * 3
        s = Similarity.from_point_pairs(a, b, c, d)
        img = s.apply_points(np.array([[*a, 0], [*b, 0]]))
        assert close(img[:, :2], np.array([c, d]))
        # Eq. 2.5: F = Spiral(Angle(BG, BD), |BD|/|BG|, B) ∘ A with G = A + CD
        g = a + (d - c)
        bg, bd = complex(*(g - b)), complex(*(d - b))
        f = complex(*b) + (bd / bg) * (complex(*a) - complex(*b))
        assert close(s.point[:2], [f.real, f.imag], 1e-7)
        ab, cd = b - a, d - c  # alpha = Angle(AB, CD), s = |CD| / |AB|
        assert s.angle == pytest.approx(math.atan2(ab[0] * cd[1] - ab[1] * cd[0], ab @ cd))
        assert s.factor == pytest.approx(np.linalg.norm(cd) / np.linalg.norm(ab))


def test_planar_point_pairs_translation_case():
    s = Similarity.from_point_pairs([0, 0], [1, 0], [2, 3], [3, 3])
    assert s.kind == "translation" and close(s.apply_points([0, 0, 0]), [2, 3, 0])


@pytest.mark.parametrize("build, message", [
    (lambda: Rotation(1, Vec(0, 0, 0), Pt(0, 0, 0)), "zero vector"),
    (lambda: Scaling(0, Pt(0, 0, 0)), "positive"),
    (lambda: Scaling(-2, Pt(0, 0, 0)), "positive"),
    (lambda: Swirl(float("nan"), Vec(0, 0, 1), Pt(0, 0, 0), 2), "finite"),
    (lambda: Translation(Vec(0, float("inf"), 0)), "finite"),
    (lambda: Similarity.from_matrix(np.diag([1.0, 2.0, 1.0, 1.0])), "not a similarity"),
    (lambda: Similarity.from_matrix(np.diag([1.0, 1.0, -1.0, 1.0])), "orientation"),
    (lambda: Similarity.from_point_pairs([0, 0], [0, 0], [1, 1], [2, 2]), "coincide"),
])
def test_bad_input_is_named(build, message):
    with pytest.raises(PleError, match=message):
        build()


def test_to_code_round_trips_through_the_program_api():
    from ple.program.runtime import API
    for s in [Swirl(0.224, Vec(0, 1, 0), Pt(10.872, 0, 0.039), 0.953), Screw(1, Vec(0, 0, 1), Pt(1, 2, 3), 0.5),
              Translation(Vec(1, 0, 0)), Scaling(1.187, Pt(-3.333, 0, 0)), Similarity()]:
        assert close(eval(s.to_code(12), dict(API)).matrix, s.matrix, 1e-10)  # noqa: S307
