"""The add-on as a Blender user lives in it (issue 15), headless bpy 5.0.1 from the installed zip.

The cases run in the test run's one Blender worker (``conftest.py``): the zip installed once, every
case from an empty scene; a crash or hang costs only its own case. ``region_budget`` measures this
process's peak memory, so it runs in a fresh process of its own. Truth comes from the core package
installed in the environment (an independent copy of the vendored one) and from numbers computed here.
"""

from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
import test_addon as base
from test_addon import (  # noqa: F401 - bpy-side helpers the cases use
    new_rig,
    part,
    region_arrays,
    update,
)

CASES = ["becots_redraw", "becots_apply_presets", "becots_named_return", "becots_round_trip",
         "cumulative_off_then_counts", "lil_follows_coarse", "absurd_counts", "region_budget",
         "move_before_run_program", "trust_survives_rename", "shift_d_copy", "duplicate_operator",
         "delete_root", "scripted_rig_deleted", "remove_operator", "cursor", "frame_precision",
         "apply_in_branch", "poll",
         "program_time_limit", "tessellate_budget", "bake", "materials_and_sizes", "render_colours",
         "program_file", "menu_keymap_prefs", "tessellate_steps", "live_errors_reported", "trust_per_file",
         "refusal_stays_until_next_edit", "reenabled_addon_edits_live", "reload_keeps_slider_values",
         "cumulative_counts_keep_span", "trust_after_file_new", "trust_not_for_changed_program",
         "slider_clamped_to_range"]
FRESH = {"region_budget"}
ADDON = "bl_ext.user_default.ple"  # peak memory of the process: only a fresh one measures this case alone


@pytest.mark.parametrize("case", CASES)
def test_addon_live(run_case, case):
    run_case(__file__, case, fresh=case in FRESH)


def test_a_bad_frame_is_named_once(run_case):
    run_case(__file__, "bad_frame_named_once")


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
bpy = ple_ext = core = None


def assert_region_is(rig, lat, region, atol=1e-5):
    co, rad, ed = region_arrays(rig)
    ev = lat.evaluate(region)
    assert co.shape == ev.center.shape, (co.shape, ev.center.shape)
    err = np.abs(co - ev.center).max() if len(co) else 0.0
    assert err <= atol * max(1, np.abs(ev.center).max()), err
    assert np.allclose(rad, ev.radius, rtol=1e-5)
    assert np.array_equal(ed, ev.beam_nodes)


def stepped_op(cls, **props):
    """A stand-in for a running SteppedOperator of class ``cls`` (Blender operators cannot be
    made by hand): its ``steps`` generator is what the modal run advances on each timer tick."""
    import types

    op = types.SimpleNamespace(rig="", beyond_limit=False, report=lambda *a: None, result="", **props)
    for name in ("steps", "mesh_job", "file_job", "subject", "mesh_object"):
        if hasattr(cls, name):
            setattr(op, name, types.MethodType(getattr(cls, name), op))
    return op


def fails(op, match, **kw):
    """Run an operator that must report an error (bpy raises RuntimeError with the report)."""
    try:
        res = op(**kw)
    except RuntimeError as exc:
        assert match in str(exc), str(exc)
        return str(exc)
    raise AssertionError(f"expected an error report, got {res}")


def matrix(obj):
    return np.array(obj.matrix_basis, dtype=float)


def world(obj):
    return np.array(obj.matrix_world, dtype=float)


def region_text(rig, lat):
    lo, hi = tuple(rig.ple.region_min), [min(a, b) for a, b in zip(rig.ple.region_max, lat.counts)]
    return f"{lo[0]}:{hi[0]},{lo[1]}:{hi[1]},{lo[2]}:{hi[2]}"


def rerun(rig):
    """The rig's program text run by the environment's core with the rig's inputs."""
    params = {k[4:]: v for k, v in rig.items() if k.startswith("ple:")}
    return core.compile_program(rig.ple.text.as_string()).run(**params)


def select_only(*objs):
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0] if objs else None


# ----- BeCOTS ------------------------------------------------------------------------------------------
def case_becots_redraw():
    """Second redraw of a BeCOTS rig: corners follow the program; a drag keeps the slider's change."""
    rig = new_rig("becots_triangle")
    rig.ple.region_max = (5, 5, 1)  # the second redraw (raised TypeError in sync_nodes)
    update()
    assert rig.ple.status == "", rig.ple.status
    rig["ple:lift"] = 2.0
    rig.update_tag()
    update()
    p = ple_ext.rig.model.parts(rig)
    assert np.allclose(matrix(p[("corner", "C")])[:3, 3], [5, 5, 2.0], atol=1e-6)  # C follows the slider
    assert np.allclose(matrix(p[("node", 0)])[:3, 3], core.load_lattice(
        "becots_triangle", {"lift": 2.0}).nodes[0].center, atol=1e-5)
    p[("corner", "A")].location = (0.1, 0.0, 0.0)  # a corner drag must not write a stale C back
    update()
    assert rig.ple.status == "", rig.ple.status
    edit = ple_ext.rig.model.edits_of(rig)[-1]
    assert np.allclose(edit.corners[2], [5, 5, 2.0], atol=1e-6) and np.allclose(edit.corners[0], [0.1, 0, 0])
    lat = core.load_lattice("becots_triangle", {"lift": 2.0})
    c = lat.becots.to_ir()["corners"]
    lat.set_becots(core.Pt(0.1, 0, 0), core.Pt(*c[1]), core.Pt(*c[2]), core.Pt(*c[3]), counts=(12, 12))
    assert_region_is(rig, lat, region_text(rig, lat))


def _drag_apply_rerun(preset):
    rig = new_rig(preset, region=(4, 4, 2))
    p = ple_ext.rig.model.parts(rig)
    c = matrix(p[("corner", "C")])[:3, 3]
    p[("corner", "C")].location = tuple(c + [0.5, -0.25, 0.4])
    update()
    assert rig.ple.status == "", (preset, rig.ple.status)
    gui = ple_ext.rig.model.lattice_of(rig)
    co0, _, _ = region_arrays(rig)
    assert bpy.ops.ple.program_apply() == {"FINISHED"}, preset
    assert rig.ple.status == "" and rig.ple.edits == "[]", (preset, rig.ple.status)
    assert "set_becots(" in rig.ple.text.as_string()
    again = rerun(rig)
    assert core.program.snippets.lattices_close(again, gui, 1e-9), preset
    ev = again.evaluate(region_text(rig, again))
    assert np.abs(ev.center - co0).max() < 1e-6 * max(1, np.abs(co0).max()), preset  # the drawing, within 1e-6
    assert np.allclose(region_arrays(rig)[0], co0, atol=1e-6)
    return rig


def case_becots_apply_presets():
    """program_apply on every becots_* preset whose slab has plain corners (was: must end with return <name>)."""
    done = []
    for name in core.program.presets.preset_names():
        if not name.startswith("becots_"):
            continue
        if not ple_ext.rig.model.becots_corners(core.load_lattice(name)):
            continue  # stacked / closed slabs have no corner handles
        _drag_apply_rerun(name)
        done.append(name)
    assert len(done) >= 3, done


def case_becots_named_return():
    """A program ending ``lat = becots_lattice(...); return lat`` applies cleanly (was: a traceback)."""
    src = core.program.presets.preset_path("becots_triangle").read_text()
    src = src.replace("    return becots_lattice(", "    lat = becots_lattice(").rstrip() + "\n    return lat\n"
    text = bpy.data.texts.new("named.py")
    text.from_string(src)
    assert bpy.ops.ple.lattice_add(source="TEXT", text="named.py") == {"FINISHED"}
    rig = bpy.context.active_object
    rig.ple.region_max = (5, 5, 1)
    update()
    p = ple_ext.rig.model.parts(rig)
    p[("corner", "B")].location = (0.5, 4.5, 0.0)
    update()
    gui = ple_ext.rig.model.lattice_of(rig)
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    assert rig.ple.status == ""
    assert core.program.snippets.lattices_close(rerun(rig), gui, 1e-9)
    assert rig.ple.text.as_string().count("return lat") == 1


def case_becots_round_trip():
    """Corner drags, lift slider, Apply, re-run: the drawing is reproduced within 1e-6."""
    rig = new_rig("becots_triangle", region=(12, 12, 1))
    p = ple_ext.rig.model.parts(rig)
    p[("corner", "D")].location = (4.7, -0.5, 0.1)
    update()
    rig["ple:lift"] = 1.3
    rig.update_tag()
    update()
    p[("corner", "B")].location = (0.2, 4.2, 0.35)
    update()
    assert rig.ple.status == ""
    co0, rad0, ed0 = region_arrays(rig)
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    assert bpy.ops.ple.program_run() == {"FINISHED"}
    co1, rad1, ed1 = region_arrays(rig)
    assert np.array_equal(ed0, ed1) and np.abs(co1 - co0).max() < 1e-6 and np.abs(rad1 - rad0).max() < 1e-6
    ev = rerun(rig).evaluate("0:12,0:12,0:1")
    assert np.abs(ev.center - co0).max() < 1e-6
    text = rig.ple.text.as_string()
    assert "Pt(4.7, -0.5, 0.1)" in text and "Pt(0.2, 4.2, 0.35)" in text, text  # no float32 noise


# ----- geometry that must not change behind the user's back ---------------------------------------------
def case_cumulative_off_then_counts():
    """Cumulative U, move U by 4.5, cumulative off, counts (4, 10, 10): group 1 stays put."""
    rig = new_rig("cubic", region=(4, 1, 1))
    rig.ple.cumulative = (True, False, False)
    fu = part(rig, "u")
    fu.location = (fu.location[0] + 4.5, fu.location[1], fu.location[2])  # the span 0..9 grows from 9 to 13.5
    update()
    x = np.sort(region_arrays(rig)[0][:, 0])
    assert np.allclose(x, [0, 1.5, 3.0, 4.5], atol=1e-5), x
    rig.ple.cumulative = (False, False, False)
    assert np.allclose(np.sort(region_arrays(rig)[0][:, 0]), x, atol=1e-5)  # a display toggle only
    assert np.allclose(matrix(fu)[:3, 3], [1.5, 0, 0], atol=1e-5)  # now shows the step
    rig.ple.counts = (4, 10, 10)
    x2 = np.sort(region_arrays(rig)[0][:, 0])
    assert np.allclose(x2, [0, 1.5, 3.0, 4.5], atol=1e-5), x2
    assert not ple_ext.rig.model.edits_of(rig)[-1].cumulative
    # the other way: cumulative on keeps the span from group 0 to the last group (4.5 over 3 steps)
    rig.ple.cumulative = (True, False, False)
    assert np.allclose(matrix(fu)[:3, 3], [4.5, 0, 0], atol=1e-5)
    rig.ple.counts = (10, 10, 10)
    x3 = np.sort(region_arrays(rig)[0][:, 0])
    assert np.allclose(x3, [0, 0.5, 1.0, 1.5], atol=1e-5), x3


def case_cumulative_counts_keep_span():
    """A fresh rig, Cumulative on for U with no drag, U count 7 -> 14: the U frame and the last
    group keep the span from group 0 to the last group (the step becomes its 13th root)."""
    rig = new_rig("fig6_3")
    fu = part(rig, "u")
    rig.ple.cumulative = (True, False, False)
    frame = matrix(fu)
    last = ple_ext.rig.model.lattice_of(rig).evaluate("6:7,0:1,0:1").center
    rig.ple.counts = (14, 12, 15)
    assert rig.ple.status == "" and tuple(rig.ple.counts) == (14, 12, 15), rig.ple.status
    assert np.allclose(matrix(fu), frame, atol=1e-5), (matrix(fu), frame)
    lat = ple_ext.rig.model.lattice_of(rig)
    assert np.allclose(lat.evaluate("13:14,0:1,0:1").center, last, atol=1e-9)
    want = core.load_lattice("fig6_3")
    want.set_u(14, want.u.incremental ** 6, cumulative=True)
    assert np.allclose(lat.evaluate("0:14,0:2,0:2").center, want.evaluate("0:14,0:2,0:2").center, atol=1e-9)
    edit = [e for e in ple_ext.rig.model.edits_of(rig) if e.axis == "u"][-1]
    assert edit.cumulative and edit.count == 14, edit  # the stored edit says what the toggle shows
    rig.ple.counts = (7, 12, 15)  # and back: the span still, so the step of the program again
    assert np.allclose(matrix(fu), frame, atol=1e-5)
    assert np.allclose(ple_ext.rig.model.lattice_of(rig).evaluate("0:7,0:2,0:2").center,
                       core.load_lattice("fig6_3").evaluate("0:7,0:2,0:2").center, atol=1e-9)


def case_lil_follows_coarse():
    """A LiL-filtered rig follows its coarse rig's location, sliders and frames."""
    fine = new_rig("cubic", region=(10, 10, 10))
    coarse = new_rig("fig6_3")
    coarse.location = (2, 2, 0)
    update()
    assert bpy.ops.ple.lil_filter(rig=fine.name, coarse=coarse.name) == {"FINISHED"}
    lat_f = core.load_lattice("cubic")

    def want(thickness=0.0645, at=(2, 2, 0), u=None):
        c = core.load_lattice("fig6_3", {"thickness": thickness})
        if u is not None:
            c.set_u(c.u.count, u)
        c.set_placement(core.Translation(core.Vec(*at)) @ c.placement)
        return core.filters.lil(lat_f, c).evaluate("0:10,0:10,0:10").center

    def got():
        return region_arrays(fine)[0]

    n0 = len(got())
    assert np.allclose(got(), want(), atol=1e-5)
    coarse.location = (3, 2.5, 0)  # the coarse rig moves
    update()
    assert np.allclose(got(), want(at=(3, 2.5, 0)), atol=1e-5) and len(got()) != n0
    coarse["ple:thickness"] = 0.12  # a slider of the coarse rig
    coarse.update_tag()
    update()
    assert got().shape == want(0.12, (3, 2.5, 0)).shape and np.allclose(got(), want(0.12, (3, 2.5, 0)), atol=1e-5)
    fu = part(coarse, "u")  # a frame of the coarse rig
    fu.location = (fu.location[0] + 0.3, fu.location[1], fu.location[2])
    update()
    u = ple_ext.rig.model.lattice_of(coarse).u.similarity
    w = want(0.12, (3, 2.5, 0), u=core.algebra.similarity.similarity_from_dict(u.to_dict()))
    assert got().shape == w.shape and np.allclose(got(), w, atol=1e-5)


def case_absurd_counts():
    """Counts the core refuses are not stored: the slider goes back, later moves still work."""
    rig = new_rig("cubic", region=(2, 2, 2))
    edits0 = rig.ple.edits
    rig.ple.counts = (10**8, 10, 10)
    assert tuple(rig.ple.counts) == (10, 10, 10), tuple(rig.ple.counts)
    assert "absurd" in rig.ple.status and rig.ple.edits == edits0, (rig.ple.status, rig.ple.edits)
    part(rig, "v").location = (0, 1.25, 0)
    update()
    assert rig.ple.status == "", rig.ple.status
    want = core.load_lattice("cubic")
    want.set_v(10, core.Translation(core.Vec(0, 1.25, 0)))
    assert_region_is(rig, want, "0:2,0:2,0:2")


def case_region_budget():
    """Counts 10^4 and a 400^3 region: refused with an estimate before any memory is used."""
    import resource

    rig = new_rig("cubic", region=(3, 3, 3))
    rig.ple.counts = (10**4, 10**4, 10**4)
    assert tuple(rig.ple.counts) == (10**4,) * 3, rig.ple.status
    co0, _, _ = region_arrays(rig)
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rig.ple.region_max = (400, 400, 400)
    status = rig.ple.status
    assert "refused" in status and "64 M" in status and "balls" in status and "GiB" in status, status
    lat = ple_ext.rig.model.lattice_of(rig)
    est = core.model.budget.estimate(lat, "0:400,0:400,0:400")
    assert est.balls == 400**3 and est.beams == 3 * 400 * 400 * 399  # exact, independently counted
    assert tuple(rig.ple.region_max) == (3, 3, 3)  # the refused region is not kept
    assert np.array_equal(region_arrays(rig)[0], co0)  # the last drawing stays
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0 < 200_000  # < 200 MB more (kB units)
    part(rig, "u").location = (1.5, 0, 0)  # the rig still works
    update()
    assert rig.ple.status == "" and np.isclose(np.sort(region_arrays(rig)[0][:, 0])[-1], 3.0, atol=1e-5)
    # a limit the user sets in the preferences
    prefs = bpy.context.preferences.addons["bl_ext.user_default.ple"].preferences
    prefs.memory_gb = 0.001  # 1 MB: a 10^3 region (1000 balls, 2700 beams, about 1.2 MB) is refused
    rig.ple.region_max = (10, 10, 10)
    assert "refused" in rig.ple.status and tuple(rig.ple.region_max) == (3, 3, 3), rig.ple.status
    fails(bpy.ops.ple.lattice_add, "refused", source="PRESET", preset="cubic", region=(10, 10, 10))


def case_move_before_run_program():
    """An untrusted file: a frame moved before Run Program is kept, not snapped back."""
    tmp = Path(tempfile.mkdtemp())
    rig = new_rig("cubic", region=(2, 2, 2))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "f.blend"))
    ple_ext.session.SESSION.trusted.clear()  # as in a new session
    bpy.ops.wm.open_mainfile(filepath=str(tmp / "f.blend"))
    rig = bpy.data.objects["cubic"]
    assert not bpy.context.preferences.filepaths.use_scripts_auto_execute
    fu = part(rig, "u")
    fu.location = (2.0, 0, 0)
    update()
    assert "trust" in rig.ple.status and "kept" in rig.ple.status, rig.ple.status
    select_only(rig)
    assert bpy.ops.ple.program_run() == {"FINISHED"}
    assert np.allclose(matrix(fu)[:3, 3], [2.0, 0, 0], atol=1e-6)  # not snapped back
    want = core.load_lattice("cubic")
    want.set_u(10, core.Translation(core.Vec(2, 0, 0)))
    assert_region_is(rig, want, "0:2,0:2,0:2")


def case_trust_survives_rename():
    rig = new_rig("cubic", region=(2, 2, 2))
    rig.name = "renamed"
    rig["ple:n"] = 4
    rig.update_tag()
    update()
    assert rig.ple.status == "" and tuple(rig.ple.counts) == (4, 4, 4), rig.ple.status


def case_trust_per_file():
    """Trust given in one .blend does not carry into another file holding the same rig id (a
    copy of the file edited elsewhere); reopening the file it was given in keeps it."""
    import shutil

    tmp = Path(tempfile.mkdtemp())
    rig = new_rig("cubic", region=(2, 2, 2))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "a.blend"))
    bpy.ops.wm.open_mainfile(filepath=str(tmp / "a.blend"))
    rig = bpy.data.objects["cubic"]
    assert ple_ext.rig.model.trusted(rig) and rig.ple.status == ""
    shutil.copy(tmp / "a.blend", tmp / "b.blend")
    bpy.ops.wm.open_mainfile(filepath=str(tmp / "b.blend"))
    rig = bpy.data.objects["cubic"]
    assert not ple_ext.rig.model.trusted(rig) and "trust" in rig.ple.status, rig.ple.status


def _drag_u_works(rig):
    """A drag of U redraws the region (the rig is trusted: its program runs without Run Program)."""
    fu = part(rig, "u")
    fu.location = (2.0, 0, 0)
    update()
    assert rig.ple.status == "", rig.ple.status
    want = rerun(rig)
    want.set_u(10, core.Translation(core.Vec(2, 0, 0)))
    assert_region_is(rig, want, "0:2,0:2,0:2")


def case_trust_after_file_new():
    """Trust given in a file survives File › New (``read_homefile``) and reopening it: drags work
    without Run Program."""
    tmp = Path(tempfile.mkdtemp())
    new_rig("cubic", region=(2, 2, 2))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "a.blend"))
    bpy.ops.wm.read_homefile()
    assert not ple_ext.rig.model.all_rigs()
    bpy.ops.wm.open_mainfile(filepath=str(tmp / "a.blend"))
    rig = bpy.data.objects["cubic"]
    assert ple_ext.rig.model.trusted(rig) and rig.ple.status == "", rig.ple.status
    _drag_u_works(rig)


def case_trust_not_for_changed_program():
    """Trust never survives a file whose program changed on disk since it was trusted (the same
    path, the same rig id, another program): neither after File › New nor on a direct reopen."""
    import shutil

    tmp = Path(tempfile.mkdtemp())
    rig = new_rig("cubic", region=(2, 2, 2))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "a.blend"))
    text = rig.ple.text
    text.from_string(text.as_string().replace("radius * cell", "1.5 * radius * cell"))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp / "changed.blend"), copy=True)  # the program changed elsewhere
    shutil.copy(tmp / "changed.blend", tmp / "a.blend")
    for leave in (None, bpy.ops.wm.read_homefile):  # a direct reopen, then File › New and reopen
        if leave is not None:
            leave()
        bpy.ops.wm.open_mainfile(filepath=str(tmp / "a.blend"))
        rig = bpy.data.objects["cubic"]
        assert not ple_ext.rig.model.trusted(rig) and "trust" in rig.ple.status, rig.ple.status
    select_only(rig)
    assert bpy.ops.ple.program_run() == {"FINISHED"}  # the new program trusted, in this file
    bpy.ops.wm.read_homefile()
    bpy.ops.wm.open_mainfile(filepath=str(tmp / "a.blend"))
    rig = bpy.data.objects["cubic"]
    assert ple_ext.rig.model.trusted(rig) and rig.ple.status == "", rig.ple.status
    _drag_u_works(rig)


def case_shift_d_copy():
    """Shift+D on a rig (root only, or root and parts): the copy has its own program text, parts
    and trust; Apply on the copy leaves the original's program alone."""
    rig = new_rig("cubic", region=(2, 2, 2))
    source = rig.ple.text.as_string()
    for with_parts in (False, True):
        select_only(rig, *(rig.children_recursive if with_parts else ()))
        with bpy.context.temp_override(active_object=rig, selected_objects=bpy.context.selected_objects):
            assert bpy.ops.object.duplicate() == {"FINISHED"}
        copy = next(o for o in bpy.context.selected_objects if o.ple.role == "RIG")
        assert copy != rig
        copy.location = (5, 0, 0)
        update()
        assert copy.ple.uid != rig.ple.uid and copy.ple.text != rig.ple.text
        cp = ple_ext.rig.model.parts(copy)
        assert {"G", "u", "v", "w", "cage", "region"} <= set(cp), cp
        assert all(o.ple.rig == copy for o in cp.values())
        assert not set(cp.values()) & set(ple_ext.rig.model.parts(rig).values())
        cp["u"].location = (1.75, 0, 0)
        update()
        assert copy.ple.status == "", copy.ple.status
        select_only(copy)
        assert bpy.ops.ple.program_apply() == {"FINISHED"}
        assert "1.75" in copy.ple.text.as_string() and rig.ple.text.as_string() == source
        assert np.isclose(np.sort(region_arrays(copy)[0][:, 0])[-1], 1.75, atol=1e-5)
        assert np.isclose(np.sort(region_arrays(rig)[0][:, 0])[-1], 1.0, atol=1e-5)
    # an untrusted original (a file from elsewhere): the copy is not trusted either and gets its
    # parts once the user runs its program
    ple_ext.session.SESSION.trusted.clear()
    select_only(rig)
    with bpy.context.temp_override(active_object=rig, selected_objects=[rig]):
        assert bpy.ops.object.duplicate() == {"FINISHED"}
    copy = next(o for o in bpy.context.selected_objects if o.ple.role == "RIG")
    update()
    assert "trust" in copy.ple.status and not ple_ext.rig.model.parts(copy)
    select_only(copy)
    assert bpy.ops.ple.program_run() == {"FINISHED"}
    assert {"G", "u", "v", "w", "cage", "region"} <= set(ple_ext.rig.model.parts(copy))
    assert_region_is(copy, core.load_lattice("cubic"), "0:2,0:2,0:2")
    assert not ple_ext.rig.model.trusted(rig)


def case_duplicate_operator():
    rig = new_rig("fig6_3", region=(2, 2, 2))
    select_only(rig)
    assert bpy.ops.ple.duplicate() == {"FINISHED"}
    copy = bpy.context.active_object
    assert copy != rig and copy.ple.role == "RIG" and copy.ple.text != rig.ple.text
    assert copy.ple.text.as_string() == rig.ple.text.as_string()
    lat = core.load_lattice("fig6_3")
    assert_region_is(copy, lat, "0:2,0:2,0:2")
    shift = world(copy)[:3, 3] - world(rig)[:3, 3]
    extent = np.ptp(np.concatenate([np.array([tuple(q.co)[:3] for q in sp.points])
                                    for sp in part(rig, "cage").data.splines]), axis=0)
    assert shift[0] > extent[0] and np.allclose(shift[1:], 0)  # beside the original, not overlapping it
    ple_ext.session.SESSION.trusted.discard(rig.ple.uid)  # trusts are separate
    assert ple_ext.rig.model.trusted(copy) and not ple_ext.rig.model.trusted(rig)


def _rig_objects():
    return [o for o in bpy.data.objects if o.ple.role != "NONE"]


def case_delete_root():
    """Deleting only the lattice object removes its frames, nodes, cage and region too. Done
    several times: the depsgraph update after a deletion names objects that are freed while the
    handler runs (reading them crashed Blender now and then)."""
    keep = new_rig("cubic", region=(2, 2, 2))
    n_keep = len(_rig_objects())
    for _ in range(6):
        rig = new_rig("fig6_3", region=(2, 2, 2))
        assert len(_rig_objects()) > n_keep
        select_only(rig)
        with bpy.context.temp_override(selected_objects=[rig], active_object=rig):
            assert bpy.ops.object.delete() == {"FINISHED"}
        update()
        assert len(_rig_objects()) == n_keep, [o.name for o in _rig_objects()]
        assert ple_ext.rig.model.parts(keep) and keep.ple.status == ""


def case_scripted_rig_deleted():
    """A rig built by a script (no operator: no update between building it and deleting it) whose
    lattice object is then deleted: its parts go with it at the next update, as after a delete of a
    rig the updates saw being built (the parts stayed when only fewer objects than last counted
    made the add-on look for them)."""
    keep = new_rig("cubic", region=(2, 2, 2))
    n_keep = len(_rig_objects())
    text = bpy.data.texts.new("scripted.py")
    text.write(core.program.presets.preset_path("fig6_3").read_text())
    rig = ple_ext.rig.sync.create(bpy.context, "scripted", text, region=(2, 2, 2))
    assert len(_rig_objects()) > n_keep
    bpy.data.objects.remove(rig)
    update()
    assert len(_rig_objects()) == n_keep, [o.name for o in _rig_objects()]
    assert ple_ext.rig.model.parts(keep) and keep.ple.status == ""


def case_remove_operator():
    keep = new_rig("cubic", region=(2, 2, 2))
    n_keep, meshes = len(_rig_objects()), len(bpy.data.meshes)
    rig = new_rig("octet", region=(2, 2, 2))
    text = rig.ple.text
    select_only(rig)
    assert bpy.ops.ple.remove() == {"FINISHED"}
    assert len(_rig_objects()) == n_keep and len(bpy.data.meshes) == meshes
    assert text.name in bpy.data.texts  # the program is kept
    assert ple_ext.rig.model.parts(keep)


def case_cursor():
    bpy.context.scene.cursor.location = (3.0, -4.0, 5.0)
    rig = new_rig("cubic", region=(2, 2, 2))
    assert np.allclose(world(rig)[:3, 3], [3, -4, 5])
    reg = part(rig, "region")
    co = region_arrays(rig)[0] @ world(reg)[:3, :3].T + world(reg)[:3, 3]
    ev = core.load_lattice("cubic").evaluate("0:2,0:2,0:2")
    assert np.allclose(co, ev.center + [3, -4, 5], atol=1e-5)


def _numbers(code):
    return re.findall(r"-?\d+\.\d+(?:e-?\d+)?", code)


def case_frame_precision():
    """Applied numbers carry the precision of the float32 frame, not its noise (0.300000014338)."""
    rig = new_rig("cubic", region=(3, 3, 3))
    fu, fv = part(rig, "u"), part(rig, "v")
    fu.location = (1.3, 0.3, 0.0)
    update()
    fv.rotation_euler = (0.0, 0.0, 0.3)
    update()
    fv.location = (0.1, 1.2, 0.0)
    update()
    gui = ple_ext.rig.model.lattice_of(rig)
    co0 = region_arrays(rig)[0]
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    text = rig.ple.text.as_string()
    assert "Translation(Vec(1.3, 0.3, 0))" in text, text
    long = [n for n in _numbers(text) if len(n.lstrip("-").replace(".", "").lstrip("0")) > 8]
    assert not long, long  # at most 8 significant digits: float32 carries about 7
    again = rerun(rig)
    assert core.program.snippets.lattices_close(again, gui, 1e-9)
    assert np.abs(again.evaluate("0:3,0:3,0:3").center - co0).max() < 1e-6
    fu_world = matrix(fu)
    assert np.allclose(fu_world[:3, 3], [1.3, 0.3, 0], atol=1e-6)  # the frame did not jump


def case_apply_in_branch():
    """Apply on the warped preset (set_u inside if/else) rewrites the branch that ran, in place:
    applying again adds no dead lines."""
    rig = new_rig("warped", region=(3, 3, 3))
    original = rig.ple.text.as_string()
    n_calls = original.count("lat.set_u(")
    fu = part(rig, "u")
    for step in range(3):
        fu.rotation_euler = (0.0, 0.05 * (step + 1), 0.0)
        update()
        assert rig.ple.status == "", rig.ple.status
        gui = ple_ext.rig.model.lattice_of(rig)
        assert bpy.ops.ple.program_apply() == {"FINISHED"}
        text = rig.ple.text.as_string()
        assert text.count("lat.set_u(") == n_calls, text
        assert core.program.snippets.lattices_close(rerun(rig), gui, 1e-9)
    assert "lat.set_u(n, Translation(Vec(span, 0, 0)), cumulative=True)" in text  # the branch not taken stays
    assert text.count("\n") == original.count("\n")


def case_poll():
    bpy.ops.object.select_all(action="DESELECT") if bpy.context.view_layer.objects else None
    bpy.context.view_layer.objects.active = None
    for op in ("program_apply", "program_run", "snippet_copy", "tessellate", "export", "remove", "duplicate",
               "bake", "node_add", "lil_filter"):
        assert not getattr(bpy.ops.ple, op).poll(), op
    assert bpy.ops.ple.lattice_add.poll()
    rig = new_rig("cubic", region=(2, 2, 2))
    assert bpy.ops.ple.program_apply.poll() and bpy.ops.ple.remove.poll()
    other = bpy.data.objects.new("plain", None)
    bpy.context.scene.collection.objects.link(other)
    select_only(other)
    assert not bpy.ops.ple.snippet_copy.poll()
    select_only(part(rig, "u"))  # a frame of the rig counts
    assert bpy.ops.ple.snippet_copy.poll()


def case_program_time_limit():
    """``while True: pass`` is stopped by the time limit with a report; nothing is created or lost."""
    prefs = bpy.context.preferences.addons["bl_ext.user_default.ple"].preferences
    assert prefs.program_seconds > 0
    prefs.program_seconds = 0.5
    text = bpy.data.texts.new("loop.py")
    text.from_string("def lattice():\n    while True:\n        pass\n")
    before = len(bpy.data.objects)
    msg = fails(bpy.ops.ple.lattice_add, "time limit", source="TEXT", text="loop.py")
    assert "loop.py" in msg and len(bpy.data.objects) == before
    rig = new_rig("cubic", region=(2, 2, 2))  # a running rig whose program is edited into a loop
    co0 = region_arrays(rig)[0]
    src = rig.ple.text.as_string()
    rig.ple.text.from_string(src.replace("    lat = Lattice()", "    while n > 0:\n        n = n + 1\n"
                                                                    "    lat = Lattice()"))
    fails(bpy.ops.ple.program_run, "time limit")
    assert "time limit" in rig.ple.status and np.array_equal(region_arrays(rig)[0], co0)
    rig.ple.text.from_string(src)
    assert bpy.ops.ple.program_run() == {"FINISHED"} and rig.ple.status == ""


def case_tessellate_budget():
    """A refined tessellation of 10^3 (8 M triangles) is refused beyond the triangle limit, with
    the estimate, in the Info report and the panel's status line."""
    rig = new_rig("cubic", region=(10, 10, 10))
    prefs = bpy.context.preferences.addons["bl_ext.user_default.ple"].preferences
    prefs.max_triangles = 2_000_000
    meshes = len(bpy.data.meshes)
    msg = fails(bpy.ops.ple.tessellate, "refused", style="REFINED")
    assert "triangles" in msg and "M" in msg and rig.ple.status and "refused" in rig.ple.status
    assert len(bpy.data.meshes) == meshes
    lat = core.load_lattice("cubic")
    from ple.app import pipeline

    est = pipeline.estimate(pipeline.plan(pipeline.MeshRequest(lat, "0:10,0:10,0:10", "refined")))
    assert 0.5 * 8_138_240 < est.triangles < 2 * 8_138_240  # the measured refined count (docs/tessellation.md)
    tmp = Path(tempfile.mkdtemp())
    fails(bpy.ops.ple.export, "refused", filepath=str(tmp / "x.stl"), style="REFINED")
    assert not list(tmp.iterdir())
    rig.ple.region_max = (2, 2, 2)
    assert bpy.ops.ple.tessellate(style="CHOCC") == {"FINISHED"}  # small work goes through
    prefs.max_triangles = 1000  # 2x2x2 CHoCC: about 1,500 triangles estimated
    n = len(bpy.data.objects)
    fails(bpy.ops.ple.tessellate, "refused", style="CHOCC")
    assert len(bpy.data.objects) == n
    assert bpy.ops.ple.tessellate(style="CHOCC", beyond_limit=True) == {"FINISHED"}  # the user said yes
    new = [o for o in bpy.data.objects if o.name.startswith(f"{rig.name}.chocc.")]
    assert len(bpy.data.objects) == n + 1 and len(new) == 1 and len(new[0].data.polygons) > 1000


def case_tessellate_steps():
    """Tessellation runs box by box: progress steps, Esc (closing the steps) leaves nothing
    behind, and the finished mesh is the core's tessellation of the region (welded boxes)."""
    import trimesh

    rig = new_rig("fig6_3", region=(4, 4, 3))
    meshes, objects = len(bpy.data.meshes), len(bpy.data.objects)
    op = stepped_op(bpy.types.PLE_OT_tessellate, style="CHOCC")
    steps = op.steps(bpy.context, rig)
    fracs = [next(steps) for _ in range(3)]
    assert fracs[0] == 0.0 and 0 <= fracs[1] <= fracs[2] < 1, fracs
    steps.close()  # what Esc does in the modal run
    assert (len(bpy.data.meshes), len(bpy.data.objects)) == (meshes, objects)
    assert bpy.ops.ple.tessellate(style="CHOCC") == {"FINISHED"}
    me = bpy.data.objects[f"{rig.name}.chocc"].data
    lat = core.load_lattice("fig6_3")
    want = core.meshing.tessellate.tessellate(lat, "0:4,0:4,0:3", "chocc")
    co = np.zeros(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    tri = np.zeros(len(me.polygons) * 3, np.int64)
    me.polygons.foreach_get("vertices", tri)
    got = trimesh.Trimesh(co.reshape(-1, 3), tri.reshape(-1, 3), process=False)
    assert len(got.vertices) == len(want.vertices) and len(got.faces) == len(want.faces)
    assert got.is_watertight and np.isclose(got.volume, want.volume, rtol=1e-5)


def case_live_errors_reported():
    """A problem met while live editing (a degenerate frame) reaches the status line and is
    queued for the Info editor, once per new problem."""
    rig = new_rig("cubic", region=(2, 2, 2))
    queue = ple_ext.session.SESSION.reports
    queue.clear()
    part(rig, "u").scale = (1.0, 2.0, 1.0)
    update()
    assert "frame U" in rig.ple.status
    assert len(queue) == 1 and "frame U" in queue[0] and rig.name in queue[0]
    part(rig, "u").location = (1.1, 0, 0)  # the same problem again: not reported twice
    update()
    assert len(queue) == 1
    ple_ext.session.flush_reports()  # what the timer does in the user interface
    assert queue == []


def case_bake():
    rig = new_rig("cubic", region=(2, 2, 2))
    select_only(rig)
    assert bpy.ops.ple.bake() == {"FINISHED"}
    baked = bpy.data.objects[f"{rig.name}.baked"]
    assert baked.ple.role == "NONE" and not baked.modifiers and len(baked.data.polygons) > 0
    co = np.zeros(len(baked.data.vertices) * 3)
    baked.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    ev = core.load_lattice("cubic").evaluate("0:2,0:2,0:2")
    r = ev.radius.max()
    assert np.allclose(co.min(0), ev.center.min(0) - r, atol=2e-3) and np.allclose(co.max(0), ev.center.max(0) + r,
                                                                                   atol=2e-3)
    assert baked.data.materials and baked.data.materials[0].name == "PLE region"
    part(rig, "u").location = (3, 0, 0)  # the baked mesh no longer follows the rig
    update()
    co2 = np.zeros(len(baked.data.vertices) * 3)
    baked.data.vertices.foreach_get("co", co2)
    assert np.allclose(co2.reshape(-1, 3), co)


def case_materials_and_sizes():
    rig = new_rig("thesis_regular", region=(2, 2, 2))
    cage, region = part(rig, "cage"), part(rig, "region")
    assert cage.data.bevel_depth > 0 and cage.data.materials[0].name == "PLE cage"
    dg = bpy.context.evaluated_depsgraph_get()
    drawn, mats = 0, set()  # balls and beams: instances of one mesh each (read while the depsgraph lists them)
    for inst in dg.object_instances:
        if inst.is_instance and inst.parent is not None and inst.parent.original == region:
            me = inst.object.data
            drawn += len(me.polygons) > 0
            mats |= {getattr(me.materials[i], "name", None) for i in {p.material_index for p in me.polygons}}
    ev = core.load_lattice("thesis_regular").evaluate("0:2,0:2,0:2")
    assert drawn == len(ev.center) + len(ev.beam_nodes), drawn
    assert mats == {"PLE region"}, mats
    ev_cage = cage.evaluated_get(dg).to_mesh()
    assert len(ev_cage.polygons) > 0  # a bevelled curve has faces: it renders
    for preset in ("thesis_regular", "fig6_3", "cubic"):  # 74, 30 and 9 units across
        r = new_rig(preset, region=(2, 2, 2))
        lat = core.load_lattice(preset)
        pts = np.concatenate([np.array([tuple(q.co)[:3] for q in sp.points]) for sp in part(r, "cage").data.splines])
        extent = np.ptp(pts, axis=0).max()
        steps = [np.linalg.norm(getattr(lat, a).apply_points(np.zeros((1, 3)))[0]) for a in "UVW"]
        step = np.mean(steps)
        size = part(r, "u").empty_display_size
        assert size >= min(0.025 * extent, 1.9 * step) and 0.4 * step <= size <= 2.1 * step, (preset, size, step,
                                                                                              extent)


def case_render_colours():
    """F12 of the default rig shows the cage and the region in distinct colours, with the default
    render engine (EEVEE, headless through EGL) and with Cycles."""
    scene = bpy.context.scene
    default_engine = scene.render.engine
    rig = new_rig("cubic", region=(3, 3, 3))
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    scene.collection.objects.link(cam)
    cam.location = (12, -10, 9)
    cam.rotation_euler = (1.05, 0, 0.88)
    scene.camera = cam
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    scene.collection.objects.link(sun)
    sun.rotation_euler = (0.6, 0.2, 0.5)
    scene.cycles.samples = 4
    scene.eevee.taa_render_samples = 1  # not the default 64: colours need no anti-aliasing (40 s of llvmpipe)
    scene.cycles.device = "CPU"
    scene.render.resolution_x = scene.render.resolution_y = 96
    scene.render.resolution_percentage = 100
    for engine in (default_engine, "CYCLES"):
        scene.render.engine = engine
        out = Path(tempfile.mkdtemp()) / "f12.png"
        scene.render.filepath = str(out)
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(str(out))
        px = np.array(img.pixels[:]).reshape(-1, 4)[:, :3]
        orange = (px[:, 0] > 1.6 * px[:, 2] + 0.05) & (px[:, 0] > px[:, 1])
        blue = (px[:, 2] > 1.6 * px[:, 0] + 0.05) & (px[:, 2] > px[:, 1])
        assert orange.sum() >= 5 and blue.sum() >= 20, (engine, orange.sum(), blue.sum())
    assert default_engine.startswith("BLENDER_EEVEE") and rig.ple.status == ""


def case_program_file():
    """A program added from a file stays linked to it: Save writes the applied edits to disk,
    Reload reads changes made on disk; a broken file on disk keeps the previous program."""
    tmp = Path(tempfile.mkdtemp())
    path = tmp / "mine.py"
    path.write_text(core.program.presets.preset_path("cubic").read_text())
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(path), region=(2, 2, 2)) == {"FINISHED"}
    rig = bpy.context.active_object
    assert rig.ple.filepath == str(path)
    part(rig, "u").location = (1.25, 0, 0)
    update()
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    assert "1.25" not in path.read_text()
    assert bpy.ops.ple.program_save() == {"FINISHED"}
    assert path.read_text() == rig.ple.text.as_string() and "1.25" in path.read_text()
    assert core.program.snippets.lattices_close(core.compile_program(path.read_text()).run(),
                                        ple_ext.rig.model.lattice_of(rig), 1e-9)
    path.write_text(path.read_text().replace("1.25", "1.5"))
    assert bpy.ops.ple.program_reload() == {"FINISHED"}
    assert np.isclose(np.sort(region_arrays(rig)[0][:, 0])[-1], 1.5, atol=1e-5)
    good = rig.ple.text.as_string()
    path.write_text("def lattice(:\n")
    fails(bpy.ops.ple.program_reload, "syntax error")
    assert rig.ple.text.as_string() == good
    preset_rig = new_rig("cubic")
    assert preset_rig.ple.filepath == ""
    fails(bpy.ops.ple.program_save, "not linked")


def case_menu_keymap_prefs():
    import importlib

    ui = importlib.import_module("bl_ext.user_default.ple.ui")
    assert hasattr(bpy.types, "PLE_MT_add")
    ops = []

    class Layout:
        def operator(self, idname, **kw):
            assert hasattr(bpy.ops.ple, idname.split(".")[1])
            props = type("P", (), {})()
            ops.append((idname, kw, props))
            return props

        def separator(self):
            pass

    menu = type("M", (), {"layout": Layout()})()
    for draw in getattr(ui.PLE_MT_add.draw, "_draw_funcs", [ui.PLE_MT_add.draw]):  # the menu and its appended parts
        draw(menu, bpy.context)
    presets = [p for _, kw, p in ops if getattr(p, "source", "") == "PRESET"]
    assert {p.preset for p in presets} == set(core.program.presets.preset_names())
    thumbs = ui._previews["presets"]  # the thumbnails shipped in the zip, loaded for the menu
    shipped = {p.stem for p in (ple_ext.corelink.presets.preset_dir() / "thumbnails").glob("*.png")}
    assert len(shipped) >= len(presets) - 2 and set(thumbs.keys()) == shipped
    assert all(thumbs[n].image_size[0] > 0 for n in shipped)
    if not bpy.app.background:  # icons exist only with a user interface
        assert all(kw.get("icon_value") for _, kw, p in ops if getattr(p, "preset", "") in shipped)
    assert {k for k, _, _ in ui.KEYMAP} >= {"ple.program_run", "ple.program_apply", "ple.duplicate", "ple.remove"}
    kc = bpy.context.window_manager.keyconfigs.addon
    if kc is not None:  # registered in the add-on key configuration (absent in some background builds)
        km = kc.keymaps.get("Object Mode")
        assert km is not None and {k.idname for k in km.keymap_items} >= {k for k, _, _ in ui.KEYMAP}
    prefs = bpy.context.preferences.addons["bl_ext.user_default.ple"].preferences
    assert prefs.memory_gb == 2.0 and prefs.max_triangles == 10_000_000 and prefs.program_seconds == 10.0
    assert prefs.job_seconds == 600.0


def case_refusal_stays_until_next_edit():
    """A refused region or count (beyond the work budget, absurd) is set back; its reason stays the
    status, and is reported once, through later updates until the user's next edit."""
    rig = new_rig("cubic", region=(3, 3, 3))
    rig.ple.counts = (10**4, 10**4, 10**4)
    queue = ple_ext.session.SESSION.reports
    queue.clear()
    rig.ple.region_max = (400, 400, 400)
    status = rig.ple.status
    assert "refused" in status and "beyond the memory limit" in status, status
    assert tuple(rig.ple.region_max) == (3, 3, 3)
    assert len(queue) == 1 and "refused" in queue[0] and rig.name in queue[0], queue
    for _ in range(2):
        update()
        assert rig.ple.status == status and len(queue) == 1, (rig.ple.status, queue)
    part(rig, "u").location = (1.5, 0, 0)  # the next edit: drawn, nothing wrong any more
    update()
    assert rig.ple.status == "" and np.isclose(np.sort(region_arrays(rig)[0][:, 0])[-1], 3.0, atol=1e-5)
    rig.ple.counts = (10**8, 10, 10)  # absurd counts: the slider goes back, the reason stays
    status = rig.ple.status
    assert "absurd" in status and tuple(rig.ple.counts) == (10**4,) * 3 and len(queue) == 2, (status, queue)
    update()
    assert rig.ple.status == status
    rig.ple.region_max = (2, 2, 2)  # a setting is an edit too
    assert rig.ple.status == ""


def case_reenabled_addon_edits_live():
    """Disabling and enabling the add-on keeps its rigs live: a frame drag after it moves the
    region as one before it did, with no Run Program."""
    import sys

    import addon_utils

    rig = new_rig("cubic", region=(2, 1, 1))
    name = rig.name
    part(rig, "u").location = (1.4, 0, 0)
    update()
    assert np.isclose(np.sort(region_arrays(rig)[0][:, 0])[-1], 1.4, atol=1e-5)
    addon_utils.disable(ADDON, default_set=True)
    addon_utils.enable(ADDON, default_set=True)
    ext = sys.modules[ADDON]
    rig = bpy.data.objects[name]
    u = next(o for o in rig.children_recursive if o.ple.role == "FRAME" and o.ple.frame == "u")
    u.location = (1.8, 0, 0)
    update()
    assert rig.ple.status == "", rig.ple.status
    x = np.sort(region_arrays(rig)[0][:, 0])
    assert np.isclose(x[-1], 1.8, atol=1e-5), x  # the drag moved the region (it used to stay at 1.4)
    assert ext.rig.model.edits_of(rig)[-1].similarity is not None


def case_reload_keeps_slider_values():
    """Reload after the program's inputs changed on disk: a slider keeps the user's value, its range
    and default follow the program (Reset to Default gives the new default), a new input gets a slider."""
    tmp = Path(tempfile.mkdtemp())
    path = tmp / "prog.py"
    path.write_text(base.PROGRAM)
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(path), region=(2, 2, 2)) == {"FINISHED"}
    rig = bpy.context.active_object
    rig["ple:thickness"] = 0.2  # the user's value
    rig.update_tag()
    update()
    changed = base.PROGRAM.replace("thickness: Range(0.05, 0.3) = 0.1", "thickness: Range(0.05, 0.5) = 0.15")
    changed = changed.replace("n: Range(1, 9) = 3", "n: Range(1, 9) = 3, m: Range(1, 5) = 2")
    path.write_text(changed)
    assert bpy.ops.ple.program_reload() == {"FINISHED"} and rig.ple.status == "", rig.ple.status
    ui = rig.id_properties_ui("ple:thickness").as_dict()
    assert rig["ple:thickness"] == 0.2 and ui["default"] == 0.15 and ui["max"] == 0.5, (rig["ple:thickness"], ui)
    assert rig["ple:m"] == 2 and rig.id_properties_ui("ple:m").as_dict()["max"] == 5
    assert np.allclose(region_arrays(rig)[1], 0.2)  # drawn with the user's value


def case_slider_clamped_to_range():
    """A script sets an input beyond its slider's Range (Blender limits only the slider): the
    value is clamped to the Range, drawn so, and the rig's status says so until the next edit."""
    rig = new_rig("fig6_3", region=(2, 2, 2))
    for asked, want in ((5.0, 0.12), (-1.0, 0.02)):
        rig["ple:thickness"] = asked
        rig.update_tag()
        update()
        assert rig["ple:thickness"] == want, rig["ple:thickness"]
        assert_region_is(rig, core.compile_program(rig.ple.text.as_string()).run(thickness=want), "0:2,0:2,0:2")
        status = rig.ple.status
        assert "thickness" in status and "clamped" in status and "0.02" in status and "0.12" in status, status
        update()
        assert rig.ple.status == status  # it stays until the user's next edit
    rig["ple:thickness"] = 0.05
    rig.update_tag()
    update()
    assert rig.ple.status == "" and rig["ple:thickness"] == 0.05, rig.ple.status
    assert_region_is(rig, core.compile_program(rig.ple.text.as_string()).run(thickness=0.05), "0:2,0:2,0:2")


def case_bad_frame_named_once():
    """A non-uniformly scaled frame is refused with a message naming that frame, once."""
    rig = new_rig("cubic", region=(2, 2, 2))
    part(rig, "u").scale = (1.0, 2.0, 1.0)
    update()
    status = rig.ple.status
    assert status.startswith("frame U: ") and "frame B" not in status, status
