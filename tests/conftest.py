"""Shared test helpers: random similarities and lattices built independently of ple's own code paths."""

from __future__ import annotations

import os

# one BLAS thread per process: make test runs one test process per core, and OpenBLAS threads
# spinning on tiny matrices (scipy's SLSQP) cost up to ten times the CPU. Set before pytest-xdist
# starts its processes and for every command a test starts; this process loaded numpy already
# (the Makefile sets it for a run in one process).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import pytest
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation as SciRot


def reference_matrix(kind: str, **p) -> np.ndarray:
    """4x4 matrix of a canonical similarity, composed from primitive matrices (independent of ple):
    T(P) · [s R] · T(-P), then a slide d along the axis."""
    m = np.eye(4)
    if kind == "identity":
        return m
    if kind == "translation":
        m[:3, 3] = p["vector"]
        return m
    axis = np.asarray(p.get("axis", [0, 0, 1]), float)
    axis = axis / np.linalg.norm(axis)
    angle = p.get("angle", 0.0)
    s = p.get("factor", 1.0)
    lin = s * SciRot.from_rotvec(angle * axis).as_matrix()
    point = np.asarray(p["point"], float)
    to, back = np.eye(4), np.eye(4)
    to[:3, 3], back[:3, 3] = -point, point
    core = np.eye(4)
    core[:3, :3] = lin
    slide = np.eye(4)
    slide[:3, 3] = p.get("distance", 0.0) * axis
    return slide @ back @ core @ to


finite = st.floats(-5, 5, allow_nan=False, allow_infinity=False)
vec3 = st.tuples(finite, finite, finite)
axis3 = vec3.filter(lambda v: np.linalg.norm(v) > 0.1)


@st.composite
def similarities(draw, kinds=("translation", "rotation", "scaling", "screw", "swirl")):
    """A random canonical similarity as (kind, params dict)."""
    kind = draw(st.sampled_from(kinds))
    angle = draw(st.floats(-3.0, 3.0).filter(lambda a: abs(a) > 1e-3))
    factor = draw(st.floats(0.5, 1.8).filter(lambda f: abs(f - 1) > 1e-3))
    params = {"translation": {"vector": draw(axis3)},
              "rotation": {"angle": angle, "axis": draw(axis3), "point": draw(vec3)},
              "scaling": {"factor": factor, "point": draw(vec3)},
              "screw": {"angle": angle, "axis": draw(axis3), "point": draw(vec3),
                        "distance": draw(st.floats(-2, 2).filter(lambda d: abs(d) > 1e-3))},
              "swirl": {"angle": angle, "axis": draw(axis3), "point": draw(vec3), "factor": factor}}[kind]
    return kind, params


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
