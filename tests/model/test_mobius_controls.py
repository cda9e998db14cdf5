"""Control frames of Möbius lattices (thesis §11.3), as the add-on shows them: read back from a
lattice, moved, and the lattice rebuilt; a frame as a similarity frame plus a C handle."""

from __future__ import annotations

import numpy as np
import pytest
from ple.errors import PleError
from ple.model.mobius import control_frames, frame_from_handles, frame_handles, with_control_frames
from ple.program.sources import load_lattice


def fit_mobius(src, dst) -> np.ndarray:
    """(a, b, c, d) with (a z + b) / (c z + d) taking three points to three, by the null space of
    the linear equations a z + b - w c z - w d = 0 (independent of ple's cross ratios)."""
    rows = [[z, 1, -w * z, -w] for z, w in zip(src, dst)]
    return np.linalg.svd(np.array(rows, complex))[2][-1].conj()


def test_frames_of_the_preset_are_the_ones_it_was_built_from():
    lat = load_lattice("mobius_slab", {"nu": 4, "nv": 3, "bend": 0.08})
    f = control_frames(lat)
    assert set(f) == {"X", "Y", "Z"}
    assert np.allclose(f["X"], [0, 1, 1j]) and np.allclose(f["Y"], [1, 2 + 0.08j, 0.92 + 1j])
    assert np.allclose(f["Z"], [1j, 1 + 1.08j, 2j])
    same = with_control_frames(lat, f)
    idx = lat.region().node_index(len(lat.nodes))
    assert np.allclose(same.node_balls(idx)[0], lat.node_balls(idx)[0], atol=1e-12)


def test_moved_frame_places_its_groups_by_the_mobius_map_of_its_points():
    lat = load_lattice("mobius_slab", {"nu": 4, "nv": 3})
    y = (1.1 + 0.1j, 2.0 + 0.4j, 0.8 + 1.2j)
    moved = with_control_frames(lat, {"Y": y})
    coef = fit_mobius([0, 1, 1j], y)  # group (1, 0) = U ∘ G_X = G_Y
    for n in range(len(lat.nodes)):
        c, r = moved.node_balls(np.array([[1, 0, 0, n]]))
        t = np.linspace(0, 2 * np.pi, 40)
        z = complex(*lat.nodes[n].center[:2]) + lat.nodes[n].radius * np.exp(1j * t)  # the ball's equator
        w = (coef[0] * z + coef[1]) / (coef[2] * z + coef[3])
        assert np.allclose(np.abs(w - complex(*c[0, :2])), r[0], rtol=1e-9)
    assert control_frames(moved)["Y"] == pytest.approx(y)


def test_handles_round_trip_and_a_similarity_frame_has_its_handle_on_y():
    rng = np.random.default_rng(0)
    for _ in range(50):
        frame = tuple(complex(*x) for x in rng.normal(size=(3, 2)))
        m, h = frame_handles(frame)
        assert np.allclose(frame_from_handles(m, h), frame)
        assert np.isclose(np.linalg.det(m[:3, :3]), abs(frame[1] - frame[0]) ** 3)  # a similarity
    m, h = frame_handles((1 + 1j, 1 + 3j, -1 + 1j))  # C = A + i (B - A): a similarity frame
    assert np.allclose(h, [0, 1, 0])
    with pytest.raises(PleError, match="coincide"):
        frame_handles((0, 0, 1j))
    with pytest.raises(PleError, match="distinct"):
        with_control_frames(load_lattice("mobius_slab"), {"Y": (1, 1j, 1)})
    with pytest.raises(PleError, match="not a Möbius"):
        control_frames(load_lattice("cubic"))


def test_code_of_moved_frames_runs_in_a_program():
    from ple.model.mobius import control_frames_code
    from ple.program.runtime import compile_program

    lat = load_lattice("mobius_slab", {"nu": 3, "nv": 2})
    moved = {"Y": (1.1 + 0.1j, 2.0 + 0.4j, 0.8 + 1.2j), "X": (0.1j, 1.05, 1.1j)}
    code = control_frames_code(moved)
    from ple.program.presets import preset_path

    src = preset_path("mobius_slab").read_text()  # the preset, its last line applying the frames
    src = src.replace("    return mobius_frames_lattice(", "    lat = mobius_frames_lattice(")
    src += f"    {code}\n    return lat\n"
    got = compile_program(src).run(nu=3, nv=2)
    idx = lat.region().node_index(len(lat.nodes))
    assert np.allclose(got.node_balls(idx)[0], with_control_frames(lat, moved).node_balls(idx)[0], atol=1e-9)


def test_frames_read_back_through_float32_keep_the_exact_map():
    """An undragged frame shown by Blender's float32 matrices is the program's: the lattice keeps its
    exact group map (so Export meshes as ple mesh does); a drag of 1e-4 is a move."""
    lat = load_lattice("mobius_slab", {"nu": 4, "nv": 3, "bend": 0.08})
    shown = {}
    for name, frame in control_frames(lat).items():
        m, h = frame_handles(frame)
        shown[name] = frame_from_handles(m.astype(np.float32), h.astype(np.float32))
    assert any(shown[k] != control_frames(lat)[k] for k in shown)  # float32 did round them
    same = with_control_frames(lat, shown)
    idx = lat.region().node_index(len(lat.nodes))
    assert np.array_equal(same.node_balls(idx)[0], lat.node_balls(idx)[0])  # bit for bit
    nudged = dict(shown, Y=tuple(p + 1e-4 for p in shown["Y"]))
    assert not np.array_equal(with_control_frames(lat, nudged).node_balls(idx)[0], lat.node_balls(idx)[0])
