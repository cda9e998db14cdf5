"""Möbius lattices in the add-on (ple_addon/features/mobius.py), headless bpy 5.0.1 from the installed
zip: the control frames X, Y, Z are empties with a C handle each; dragging them redraws the
lattice. Node positions are compared with the core installed in the environment (an independent
copy of the vendored one), the frames' points read off the empties with mathutils here.

The cases run in the test run's one Blender worker (``conftest.py``)."""

from __future__ import annotations

import numpy as np
import pytest
import test_addon as base  # the shared bpy-side helpers

CASES = ["mobius_drag", "mobius_tmi_and_errors", "mobius_frame_put_back"]


@pytest.mark.parametrize("case", CASES)
def test_addon_mobius(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
def positions(rig):
    me = base.ple_ext.features.mobius.parts(rig)["region"].data
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    ed = np.zeros(len(me.edges) * 2, np.int32)
    me.edges.foreach_get("vertices", ed)
    return co.reshape(-1, 3).astype(float), ed.reshape(-1, 2)


def frame_points(frame, handle):
    """A = the frame's origin, B = the tip of its x axis, C = the handle, in the rig (plane z = 0)."""
    from mathutils import Vector

    m = frame.matrix_basis
    pts = [m @ Vector((0, 0, 0)), m @ Vector((1, 0, 0)), m @ handle.matrix_basis.translation]
    return tuple(complex(p.x, p.y) for p in pts)


def assert_drawn(rig, lat):
    co, ed = positions(rig)
    ev = lat.evaluate()
    assert co.shape == ev.center.shape
    assert np.allclose(co, ev.center, atol=1e-5 * max(1.0, np.abs(ev.center).max()))
    assert np.array_equal(ed, ev.beam_nodes)


def case_mobius_drag():
    bpy, mf = base.bpy, base.ple_ext.features.mobius
    from ple.model.mobius import with_control_frames
    from ple.program.sources import load_lattice

    assert bpy.ops.ple.mobius_add(preset="mobius_slab") == {"FINISHED"}
    rig = bpy.context.active_object
    p = mf.parts(rig)
    assert {k for k in p if isinstance(k, str)} == {"X", "Y", "Z", "region"}
    lat = load_lattice("mobius_slab")
    assert_drawn(rig, lat)
    seen = []  # the panel references what exists (test_addon.CheckedLayout)
    mf.PLE_PT_mobius.draw(type("P", (), {"layout": base.CheckedLayout(seen)})(), bpy.context)
    assert "ple.mobius_snippet" in seen
    for key, pts in (("X", (0, 1, 1j)), ("Y", (1, 2 + 0.08j, 0.92 + 1j))):  # the preset's frames
        assert np.allclose(frame_points(p[key], p[("handle", key)]), pts, atol=1e-6)
    # drag Y (move, turn, scale) and bend it by its handle; drag Z
    y, hy = p["Y"], p[("handle", "Y")]
    y.location.x += 0.3
    y.rotation_euler.z += 0.15
    y.scale = (1.1, 1.1, 1.1)
    hy.location = (0.1, 1.2, 0.0)
    p["Z"].location.y += 0.2
    base.update()
    moved = {k: frame_points(p[k], p[("handle", k)]) for k in ("X", "Y", "Z")}
    assert_drawn(rig, with_control_frames(lat, moved))
    # X moves the whole slab (the template's frame)
    p["X"].location = (0.5, -0.2, 0.0)
    base.update()
    moved["X"] = frame_points(p["X"], p[("handle", "X")])
    assert_drawn(rig, with_control_frames(lat, moved))
    # the drags as program text: run it on the preset's lattice, get the drawing back
    assert bpy.ops.ple.mobius_snippet() == {"FINISHED"}
    code = bpy.data.texts["PLE snippet"].as_string()
    assert code.startswith("lat = with_control_frames(lat, {")
    ns = {"lat": load_lattice("mobius_slab"), "with_control_frames": with_control_frames}
    exec(code, ns)
    assert_drawn(rig, ns["lat"])


def case_mobius_tmi_and_errors():
    bpy, mf = base.bpy, base.ple_ext.features.mobius
    from ple.model.mobius import with_control_frames
    from ple.program.sources import load_lattice

    # Add › PLE Lattice › tmi_slab makes a Möbius rig too
    assert bpy.ops.ple.lattice_add(source="PRESET", preset="tmi_slab") == {"FINISHED"}
    rig = bpy.context.active_object
    p = mf.parts(rig)
    lat = load_lattice("tmi_slab")
    assert_drawn(rig, lat)
    p["Y"].location.x += 0.25
    base.update()
    keys = [k for k in p if isinstance(k, str) and k != "region"]
    good = with_control_frames(lat, {k: frame_points(p[k], p[("handle", k)]) for k in keys})
    assert_drawn(rig, good)
    # a degenerate frame (its handle on its origin): the error is the rig's status, the drawing stays
    p[("handle", "Y")].location = (0.0, 0.0, 0.0)
    base.update()
    assert "distinct" in rig["ple_status"]
    assert_drawn(rig, good)
    p[("handle", "Y")].location = (0.0, 1.0, 0.0)
    base.update()
    assert rig["ple_status"] == ""
    # not a Möbius preset: an error report, nothing made
    n = len(bpy.data.objects)
    try:
        bpy.ops.ple.mobius_add(preset="cubic")
        raise AssertionError("expected an error report")
    except RuntimeError as exc:
        assert "not a Möbius lattice" in str(exc)
    assert len(bpy.data.objects) == n


def case_mobius_frame_put_back():
    """A handle moved onto its frame's origin shows the error; put back exactly where it was, the
    error clears (the frames are then the ones last drawn)."""
    bpy, mf = base.bpy, base.ple_ext.features.mobius
    assert bpy.ops.ple.mobius_add(preset="mobius_slab") == {"FINISHED"}
    rig = bpy.context.active_object
    handle = mf.parts(rig)[("handle", "Y")]
    was = tuple(handle.location)
    before = positions(rig)[0]
    handle.location = (0.0, 0.0, 0.0)
    base.update()
    assert "distinct" in rig["ple_status"], rig["ple_status"]
    handle.location = was
    base.update()
    assert rig["ple_status"] == "", rig["ple_status"]
    assert np.array_equal(positions(rig)[0], before)
