"""ple.guard: the work estimate (checked against evaluation and tessellation), the program
time limit, and numbers at the precision of a float32 frame; ple.tessellate.weld_chunks."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import similarities
from hypothesis import given, settings
from hypothesis import strategies as st
from ple import Similarity
from ple.errors import PleError
from ple.guard import Estimate, ProgramTimeoutError, check, estimate, frame_number, frame_similarity, time_limit
from ple.program import compile_program, load_lattice, preset_path
from ple.tessellate import iter_triangles, tessellate, weld_chunks

REGIONS = ["0:3,0:3,0:3", "1:4,0:2,2:5", "0:1,0:1,0:1", "0:7,0:1,0:1"]


@pytest.mark.parametrize("preset", ["cubic", "octet", "fig6_3", "kagome", "cylindrical"])
@pytest.mark.parametrize("region", REGIONS)
def test_balls_and_beams_are_exact(preset, region):
    lat = load_lattice(preset)
    spans = [tuple(int(x) for x in part.split(":")) for part in region.split(",")]
    region = ",".join(f"{min(a, c - 1)}:{min(b, c)}" for (a, b), c in zip(spans, lat.counts))
    est = estimate(lat, region)
    ev = lat.evaluate(region)
    assert (est.balls, est.beams) == (len(ev.center), len(ev.beam_nodes))
    assert est.groups == lat.region(region).groups and est.triangles == 0


@pytest.mark.parametrize("preset", ["cubic", "octet", "fig6_3"])
@pytest.mark.parametrize("style", ["chocc", "cnt"])
def test_triangle_estimate_within_a_factor_two(preset, style):
    lat = load_lattice(preset)
    got = len(tessellate(lat, "0:4,0:3,0:2", style).faces)
    est = estimate(lat, "0:4,0:3,0:2", style).triangles
    assert 0.5 * got <= est <= 2.0 * got, (got, est)


def test_huge_region_is_estimated_without_memory():
    lat = load_lattice("cubic")
    for axis in "uvw":
        d = getattr(lat, axis)
        getattr(lat, f"set_{axis}")(10**4, d.similarity)
    est = estimate(lat, "0:400,0:400,0:400")
    assert est.balls == 64_000_000 and est.beams == 3 * 400 * 400 * 399
    with pytest.raises(PleError, match=r"refused: 64 M node-groups: 64 M balls, 192 M beams, about [0-9.]+ GB"):
        check(est, max_bytes=2 * 2**30, what="drawing")
    assert check(estimate(lat, "0:3,0:3,0:3"), max_bytes=2 * 2**30) is not None


def test_triangle_limit():
    est = Estimate(1, 1, 1, 5_000_000, 10)
    with pytest.raises(PleError, match="5 M triangles.*limit of 2 M triangles"):
        check(est, max_triangles=2_000_000)


def test_time_limit_stops_a_loop_and_restores_tracing():
    prog = compile_program("def lattice():\n    while True:\n        pass\n", "loop.py")
    before = sys.gettrace()
    with pytest.raises(PleError, match="loop.py: stopped after the time limit of 0.2 s"):
        with time_limit(0.2, "loop.py"):
            prog.run()
    assert sys.gettrace() is before
    assert issubclass(ProgramTimeoutError, PleError)
    cubic = compile_program(preset_path("cubic").read_text(), "cubic.py")
    with time_limit(30.0, "cubic.py"):  # an ordinary program is unaffected
        assert cubic.run().counts == (10, 10, 10)
    with time_limit(0.2, "another.py"):  # only the named program's frames are limited
        assert cubic.run().counts == (10, 10, 10)


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
    from conftest import reference_matrix

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


@pytest.mark.parametrize("preset,style", [("cubic", "chocc"), ("fig6_3", "cnt"), ("octet", "chocc")])
def test_weld_chunks_is_the_whole_tessellation(preset, style):
    import trimesh

    lat = load_lattice(preset)
    region = "0:3,0:3,0:2"
    want = tessellate(lat, region, style)
    verts, faces = weld_chunks(iter_triangles(lat, region, style, max_groups=3))
    got = trimesh.Trimesh(verts, faces, process=False)
    assert len(got.vertices) == len(want.vertices) and len(got.faces) == len(want.faces)
    assert got.is_watertight and np.isclose(got.volume, want.volume, rtol=1e-9)
    assert np.allclose(np.sort(np.asarray(got.vertices), axis=0), np.sort(np.asarray(want.vertices), axis=0))


def test_frame_similarity_gives_back_the_short_numbers():
    from ple.geometry import Pt, Vec
    from ple.similarity import Rotation, Screw, Translation

    for sim, scale in ((Translation(Vec(1.3, 0.3, 0)), 1.3), (Rotation(0.3, Vec(0, 0, 1), Pt(0.5, 0.2, 0)), 1.0),
                       (Screw(0.2, Vec(0, 1, 0), Pt(2.5, 0, 1.5), 0.7), 2.5)):
        noisy = Similarity.from_matrix(sim.matrix.astype(np.float32).astype(float))
        assert noisy.to_code(12) != sim.to_code(12)  # float32 noise shows at 12 digits
        assert frame_similarity(noisy, scale).to_code(12) == sim.to_code(12)
