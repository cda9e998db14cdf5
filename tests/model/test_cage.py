"""Cage isocurves and frame handles (core/ple/cage.py) against matrix powers."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple import Lattice, PleError, Pt, Rotation, Scaling, Screw, Swirl, Translation, Vec
from ple.model.cage import (
    base_frame,
    cage_curves,
    cage_point,
    direction_frame,
    direction_from_frame,
    map_points,
    placement_from_frame,
)
from ple.program.sources import load_lattice
from scipy.linalg import fractional_matrix_power


def _lat(nu=4, nv=3, nw=5):
    lat = Lattice()
    lat.add_node(Pt(0, 0, 0), 0.1)
    lat.add_node(Pt(0.5, 0.2, 0.1), 0.05)
    lat.add_beam(0, 1, 0, 0, 0)
    lat.set_u(nu, Scaling(1.1, Pt(-3, 0, 0)))
    lat.set_v(nv, Rotation(0.3, Vec(0, 0, 1), Pt(-1.5, 0, 0)))
    lat.set_w(nw, Swirl(0.2, Vec(0, 1, 0), Pt(8, 0, 0), 0.95))
    lat.set_placement(Screw(0.4, Vec(1, 1, 0), Pt(0, 1, 0), 0.7))
    return lat


def test_map_at_integers_is_matrix_powers():
    lat = _lat()
    p = np.append(cage_point(lat), 1.0)
    mp = np.linalg.matrix_power
    for i, j, k in [(0, 0, 0), (1, 2, 3), (3, 2, 4), (2, 0, 1)]:
        want = lat.placement.matrix @ mp(lat.W.matrix, k) @ mp(lat.V.matrix, j) @ mp(lat.U.matrix, i) @ p
        assert np.allclose(map_points(lat, [[i, j, k]])[0], want[:3], atol=1e-12)


def test_map_at_half_steps_is_principal_square_root():
    lat = _lat()
    p = np.append(cage_point(lat), 1.0)
    g = lat.placement.matrix
    for s, col in ((lat.U, 0), (lat.V, 1), (lat.W, 2)):
        uvw = np.zeros((1, 3))
        uvw[0, col] = 0.5
        want = g @ np.real(fractional_matrix_power(s.matrix, 0.5)) @ p
        assert np.allclose(map_points(lat, uvw)[0], want[:3], atol=1e-9)


def test_cage_edges_join_block_corners():
    lat = _lat()
    curves = cage_curves(lat, interior=0)
    assert len(curves) == 12
    nu, nv, nw = (c - 1 for c in lat.counts)
    corners = map_points(lat, [[i, j, k] for i in (0, nu) for j in (0, nv) for k in (0, nw)])
    ends = np.concatenate([[c[0], c[-1]] for c in curves])
    for e in ends:  # every curve end is a block corner, every corner ends 3 edges
        assert np.min(np.linalg.norm(corners - e, axis=1)) < 1e-9
    for c in corners:
        assert np.sum(np.linalg.norm(ends - c, axis=1) < 1e-9) == 3


def test_cage_interior_lines_and_count_one():
    lat = _lat()
    assert len(cage_curves(lat, interior=1)) == 27 and len(cage_curves(lat, interior=2)) == 48
    flat = _lat(nw=1)  # a slab: no lines along w, 4 edges along u and v each
    curves = cage_curves(flat, interior=0)
    assert len(curves) == 4
    assert all(len(c) >= 2 for c in curves)
    with pytest.raises(PleError):
        cage_curves(lat, interior=-1)


def test_cage_of_translations_is_straight_and_sampled_at_groups():
    lat = load_lattice("cubic", {"n": 4})
    for c in cage_curves(lat, samples_per_group=3):
        d = c[-1] - c[0]
        off = c - c[0] - np.outer((c - c[0]) @ d / (d @ d), d)
        assert np.abs(off).max() < 1e-12
        assert len(c) == 3 * 3 + 1


sims = st.sampled_from([
    Translation(Vec(1, 0.2, 0)), Rotation(0.7, Vec(0, 0, 1), Pt(1, 0, 0)), Scaling(1.3, Pt(0, -1, 2)),
    Swirl(0.4, Vec(1, 2, 3), Pt(2, 0, 1), 0.8), Screw(2.5, Vec(0, 1, 0), Pt(0, 0, 3), 0.4)])


@settings(max_examples=30, deadline=None)
@given(sims, st.sampled_from("uvw"), st.booleans(), st.integers(1, 6))
def test_frame_round_trip(s, axis, cumulative, count):
    lat = _lat()
    getattr(lat, f"set_{axis}")(count, s)
    frame = direction_frame(lat, axis, cumulative)
    got = direction_from_frame(lat, axis, frame, cumulative)
    want = s ** (count - 1) if cumulative and count > 1 else s
    assert got.allclose(want, 1e-9)
    # the frame is the base frame moved by the similarity: origin = S(P)
    assert np.allclose(frame[:3, 3], want.apply_points(cage_point(lat)), atol=1e-9)


def test_degenerate_frames_name_the_frame():
    lat = _lat()
    squashed = base_frame(lat) @ np.diag([1.0, 2.0, 1.0, 1.0])
    with pytest.raises(PleError, match="frame U"):
        direction_from_frame(lat, "u", squashed)
    with pytest.raises(PleError, match="frame G"):
        placement_from_frame(np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(PleError, match="frame W"):
        direction_from_frame(lat, "w", np.zeros((4, 4)))
    assert placement_from_frame(lat.placement.matrix).allclose(lat.placement)


def test_float32_frames_snap_to_the_current_linear_part():
    lat = load_lattice("fig6_3")
    frame = direction_frame(lat, "u").astype(np.float32).astype(float)
    assert direction_from_frame(lat, "u", frame) == lat.U  # untouched frame: exactly the current U
    frame[:3, 3] += [0.25, 0, 0]  # dragged: same factor, new fixed point
    got = direction_from_frame(lat, "u", frame)
    assert got.kind == "scaling" and got.factor == lat.U.factor
    assert np.allclose(got.apply_points(cage_point(lat)), frame[:3, 3], atol=1e-6)
    cubic = load_lattice("cubic", {"n": 3})
    moved = direction_frame(cubic, "v").astype(np.float32).astype(float)
    moved[:3, 3] += [0.1, 0.2, 0.3]
    got = direction_from_frame(cubic, "v", moved)
    assert got.kind == "translation"
    assert np.allclose(got.apply_vectors([0, 0, 0]) + got.apply_points([0, 0, 0]), [0.1, 1.2, 0.3], atol=1e-6)
    turned = Rotation(0.3, Vec(0, 0, 1), Pt(0, 0, 0)).matrix @ direction_frame(cubic, "v")
    assert direction_from_frame(cubic, "v", turned).kind != "translation"  # real rotations are kept


def test_float32_screw_frame_stays_a_screw():
    g = Screw(0.3, Vec(0, 0, 1), Pt(1, 0, 0), 0.5)
    m32 = g.matrix.astype(np.float32).astype(float)
    got = placement_from_frame(m32)
    assert got.kind == "screw" and got.allclose(g, 1e-6)
    assert placement_from_frame(m32, previous=g) == g
