"""ple.algebra.precision: numbers and similarities at the precision of a float32 frame."""

from __future__ import annotations

import numpy as np
from conftest import reference_matrix, similarities
from hypothesis import given, settings
from hypothesis import strategies as st
from ple import PleError, Pt, Rotation, Screw, Similarity, Translation, Vec
from ple.algebra.precision import frame_number, frame_similarity


def test_frame_number_drops_float32_noise():
    assert frame_number(0.300000014338) == 0.3
    assert frame_number(float(np.float32(4.5)) + 4e-7, scale=4.5) == 4.5
    assert frame_number(3e-8, scale=5.0) == 0.0
    assert frame_number(1.2345678) == 1.2345678 or abs(frame_number(1.2345678) - 1.2345678) < 3e-7


@given(st.floats(-1e4, 1e4, allow_nan=False).filter(lambda x: abs(x) > 1e-3))
@settings(max_examples=300, deadline=None)
def test_frame_number_keeps_float32_precision(x):
    x32 = float(np.float32(x))
    y = frame_number(x32)
    assert abs(y - x32) <= max(abs(x32), 1.0) * 2.0 ** -22  # two float32 units in the last place of the frame
    assert len(repr(y).replace("-", "").replace(".", "").lstrip("0").split("e")[0]) <= 9


@given(similarities())
@settings(max_examples=100, deadline=None)
def test_frame_similarity_matches_the_float32_frame(kind_params):
    kind, params = kind_params
    m32 = reference_matrix(kind, **params).astype(np.float32).astype(float)
    try:
        sim = Similarity.from_matrix(m32)
    except (PleError, np.linalg.LinAlgError):
        return  # float32 rounding left a degenerate matrix: nothing to round
    scale = max(1.0, float(np.abs(m32[:3, 3]).max()))
    got = frame_similarity(sim, scale)
    err = np.abs(got.matrix - sim.matrix)[:3]
    assert err[:, :3].max() <= 2.0 ** -22 and err[:, 3].max() <= 2.0 ** -22 * scale, err


def test_frame_similarity_gives_back_the_short_numbers():
    for sim, scale in ((Translation(Vec(1.3, 0.3, 0)), 1.3), (Rotation(0.3, Vec(0, 0, 1), Pt(0.5, 0.2, 0)), 1.0),
                       (Screw(0.2, Vec(0, 1, 0), Pt(2.5, 0, 1.5), 0.7), 2.5)):
        noisy = Similarity.from_matrix(sim.matrix.astype(np.float32).astype(float))
        assert noisy.to_code(12) != sim.to_code(12)  # float32 noise shows at 12 digits
        assert frame_similarity(noisy, scale).to_code(12) == sim.to_code(12)
