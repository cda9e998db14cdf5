"""The Blender extension, installed from the built zip into headless bpy 5.0.1.

The cases run in the test run's one Blender worker (``conftest.py``, ``blender_worker.py``): the
zip is installed once and every case starts from an empty scene, the add-on's default preferences
and a forgotten session; a crash of one case costs only that case. Truth comes from the core
package installed in the environment (an independent copy of the vendored one). The other add-on
test modules share the helpers below (``bpy``, ``ple_ext`` and ``core`` are bound by the worker).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
PROGRAM = '''"""Test program with comments."""


def lattice(thickness: Range(0.05, 0.3) = 0.1, n: Range(1, 9) = 3):
    lat = Lattice()
    # the template node-group
    a = lat.add_node(Pt(0, 0, 0), thickness)
    lat.add_beam(a, a, 1, 0, 0)  # along U
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 0, 0, 1)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(3, Translation(Vec(0, 1, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 1)))
    return lat
'''


# ----- pytest side ------------------------------------------------------------------------------
CASES = ["install", "lattice_add_sources", "region_matches_core", "frame_moves", "cumulative_frames",
         "param_slider", "counts", "template_ops", "snippet_round_trip", "ir_apply", "no_leaks", "errors",
         "untrusted", "undo", "filters", "tessellate", "export", "ui", "becots_corners"]


@pytest.mark.parametrize("case", CASES)
def test_addon_case(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
bpy = ple_ext = core = None


def update():
    bpy.context.view_layer.update()


def new_rig(preset="cubic", **kw):
    assert bpy.ops.ple.lattice_add(source="PRESET", preset=preset, **kw) == {"FINISHED"}
    return bpy.context.active_object


def part(rig, key):
    return ple_ext.rig.model.parts(rig)[key]


def region_arrays(rig):
    """Ball centres and radii of the drawn region in the rig's coordinates (its object's matrix,
    G for a rigidly placed drawing, applied), and its beams."""
    obj = part(rig, "region")
    me = obj.data
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    rad = np.zeros(len(me.vertices), np.float32)
    if len(me.vertices):
        me.attributes["ple_radius"].data.foreach_get("value", rad)
    ed = np.zeros(len(me.edges) * 2, np.int32)
    me.edges.foreach_get("vertices", ed)
    m = np.array(obj.matrix_basis)
    factor = np.cbrt(np.linalg.det(m[:3, :3]))  # a similarity's dilation
    return (co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]).astype(np.float32), (rad * factor).astype(np.float32), \
        ed.reshape(-1, 2)


def assert_region_is(rig, lat, region):
    co, rad, ed = region_arrays(rig)
    ev = lat.evaluate(region)
    assert co.shape == ev.center.shape, (co.shape, ev.center.shape)
    assert np.allclose(co, ev.center, atol=1e-5 * max(1, np.abs(ev.center).max()))
    assert np.allclose(rad, ev.radius, rtol=1e-5)
    assert np.array_equal(ed, ev.beam_nodes)


def fails(op, match, **kw):
    """Run an operator that must report an error (bpy raises RuntimeError for it)."""
    try:
        res = op(**kw)
    except RuntimeError as exc:
        assert match in str(exc), str(exc)
        return
    raise AssertionError(f"expected an error report, got {res}")


def matrix(obj):
    return np.array(obj.matrix_basis, dtype=float)


def case_install():
    import addon_utils

    assert "bl_ext.user_default.ple" in {m.__name__ for m in addon_utils.modules()}
    assert "bl_ext.user_default.ple" in bpy.context.preferences.addons
    local = Path(os.environ["BLENDER_USER_RESOURCES"]) / "extensions" / ".local"
    assert list(local.rglob("site-packages/trimesh/__init__.py"))  # the bundled wheel was installed
    link = sys.modules["bl_ext.user_default.ple.corelink"]
    assert link.ple.__name__ == "bl_ext.user_default.ple.vendor.ple"  # the vendored core is used
    assert "/extensions/user_default/ple/vendor/ple" in link.ple.__file__
    for op in ("lattice_add", "tessellate", "lil_filter", "stencil_filter", "snippet_copy", "program_apply", "export"):
        assert hasattr(bpy.ops.ple, op)
        assert "UNDO" in getattr(bpy.types, f"PLE_OT_{op}").bl_options
    addon_utils.disable("bl_ext.user_default.ple", default_set=True)  # unregisters cleanly
    assert not hasattr(bpy.types.Object, "ple") and not hasattr(bpy.types, "PLE_OT_export")
    assert not any(getattr(h, "__module__", "").startswith("bl_ext") for h in bpy.app.handlers.depsgraph_update_post)
    addon_utils.enable("bl_ext.user_default.ple", default_set=True)
    assert hasattr(bpy.types.Object, "ple")


def case_lattice_add_sources():
    tmp = Path(tempfile.mkdtemp())
    (tmp / "prog.py").write_text(PROGRAM)
    lat = core.load_lattice("fig6_3")
    core.io.irfile.save_ir(lat, tmp / "fig.json")
    rig = new_rig("fig6_3", region=(2, 2, 2))
    assert tuple(rig.ple.counts) == (7, 12, 15) and rig.ple.source_kind == "PROGRAM"
    assert "ple:thickness" in rig.keys() and rig.id_properties_ui("ple:thickness").as_dict()["max"] == 0.12
    names = sorted(ple_ext.rig.model.parts(rig), key=str)
    assert names == sorted(["G", "u", "v", "w", "cage", "region", ("node", 0)], key=str)
    assert rig.users_collection[0].name == "PLE fig6_3"
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(tmp / "prog.py")) == {"FINISHED"}
    assert bpy.context.active_object.name == "prog" and tuple(bpy.context.active_object.ple.counts) == (3, 3, 3)
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(tmp / "fig.json")) == {"FINISHED"}
    irrig = bpy.context.active_object
    assert irrig.ple.source_kind == "IR" and tuple(irrig.ple.counts) == (7, 12, 15)
    assert_region_is(irrig, lat, "0:3,0:3,0:3")
    text = bpy.data.texts.new("mine.py")
    text.from_string(PROGRAM)
    assert bpy.ops.ple.lattice_add(source="TEXT", text="mine.py", name="mine") == {"FINISHED"}
    assert bpy.context.active_object.ple.text == text


def case_region_matches_core():
    for preset in ("fig6_3", "octet", "cylindrical"):
        rig = new_rig(preset)
        rig.ple.region_min, rig.ple.region_max = (1, 0, 2), (3, 2, 5)
        assert_region_is(rig, core.load_lattice(preset), "1:3,0:2,2:5")
        curves = part(rig, "cage").data.splines
        want = core.model.cage.cage_curves(core.load_lattice(preset), interior=1)
        assert len(curves) == len(want)
        got = np.zeros(len(curves[0].points) * 4, np.float32)
        curves[0].points.foreach_get("co", got)
        assert np.allclose(got.reshape(-1, 4)[:, :3], want[0], atol=1e-4)


def case_frame_moves():
    """Dragging, rotating and scaling the U frame, and moving G: the region follows the core."""
    rig = new_rig("fig6_3")
    lat0 = core.load_lattice("fig6_3")
    fu = part(rig, "u")
    turn = core.Rotation(0.2, core.Vec(0, 1, 1), core.Pt(0.5, 0, 0)).matrix
    new = turn @ matrix(fu) @ np.diag([1.1, 1.1, 1.1, 1.0])
    fu.matrix_basis = bpy_matrix(new)
    update()
    stored = matrix(fu)  # float32 as Blender keeps it
    base = np.eye(4)
    base[:3, 3] = lat0.template_centers.mean(axis=0)
    want = lat0.copy()
    want.set_u(7, core.Similarity.between_frames(base, stored))
    assert_region_is(rig, want, "0:3,0:3,0:3")
    assert rig.ple.status == ""
    g = part(rig, "G")
    moved = core.Screw(0.3, core.Vec(0, 0, 1), core.Pt(1, 0, 0), 0.5).matrix
    g.matrix_basis = bpy_matrix(moved)
    update()
    gm = matrix(g)  # the region is the unplaced lattice mapped by G's (float32) matrix
    co, rad, _ = region_arrays(rig)
    ev = want.evaluate("0:3,0:3,0:3")
    assert np.allclose(co, ev.center @ gm[:3, :3].T + gm[:3, 3], atol=1e-5)
    assert np.allclose(rad, ev.radius * np.cbrt(np.linalg.det(gm[:3, :3])), rtol=1e-5)
    assert np.allclose(matrix(fu), stored, atol=1e-6)  # U rides along with G, U itself unchanged


def bpy_matrix(m):
    from mathutils import Matrix

    return Matrix(np.asarray(m).tolist())


def case_cumulative_frames():
    """Cumulative frame W (Fig. 6.2): the last group lands on the frame, the rest stays steady."""
    rig = new_rig("cubic", region=(2, 2, 10))
    rig["ple:n"] = 5
    rig.update_tag()
    update()
    fw = part(rig, "w")
    assert np.allclose(matrix(fw)[:3, 3], [0, 0, 1])
    rig.ple.cumulative = (False, False, True)
    assert np.allclose(matrix(fw)[:3, 3], [0, 0, 4])  # shows W**(5-1)
    fw.location = (0, 0, 8)
    update()
    co, _, _ = region_arrays(rig)
    assert np.isclose(co[:, 2].max(), 8, atol=1e-5)
    assert np.allclose(np.unique(np.round(co[:, 2], 5)), [0, 2, 4, 6, 8])
    edits = ple_ext.rig.model.edits_of(rig)
    assert edits[-1].cumulative and edits[-1].similarity.kind == "translation"


def case_param_slider():
    rig = new_rig("fig6_3")
    _, rad0, _ = region_arrays(rig)
    rig["ple:thickness"] = 0.1
    rig.update_tag()
    update()
    _, rad1, _ = region_arrays(rig)
    assert np.allclose(rad1 / rad0, 0.1 / 0.0645, rtol=1e-5)


def case_counts():
    rig = new_rig("fig6_3")
    rig.ple.counts = (4, 12, 15)
    assert tuple(rig.ple.counts) == (4, 12, 15)
    lat = ple_ext.rig.model.lattice_of(rig)
    assert lat.counts == (4, 12, 15)
    assert bpy.ops.ple.snippet_copy() == {"FINISHED"}
    assert bpy.data.texts["PLE snippet"].as_string().startswith("lat.set_u(4, lat.u.similarity")
    assert bpy.ops.ple.edits_clear() == {"FINISHED"}  # back to what the program gives
    assert tuple(rig.ple.counts) == (7, 12, 15) and ple_ext.rig.model.edits_of(rig) == []
    assert_region_is(rig, core.load_lattice("fig6_3"), "0:3,0:3,0:3")


def case_template_ops():
    rig = new_rig("cubic", region=(2, 2, 2))
    assert bpy.ops.ple.node_add(center=(0.5, 0.5, 0), radius=0.05) == {"FINISHED"}
    p = ple_ext.rig.model.parts(rig)
    n0, n1 = p[("node", 0)], p[("node", 1)]
    assert np.allclose(matrix(n1)[:3, 3], [0.5, 0.5, 0]) and np.isclose(matrix(n1)[0, 0], 0.05)
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    n1.select_set(True)
    n0.select_set(True)
    bpy.context.view_layer.objects.active = n1
    assert bpy.ops.ple.beam_add(offset=(0, 0, 1)) == {"FINISHED"}  # picks the two selected nodes
    lat = ple_ext.rig.model.lattice_of(rig)
    b = lat.beams[-1]
    assert (b.n1, b.n2, b.di, b.dj, b.dk) == (1, 0, 0, 0, 1)  # active node first
    n1.location = (0.5, 0.25, 0.1)  # move a template node
    n1.scale = (0.08, 0.08, 0.08)
    update()
    want = core.load_lattice("cubic")
    want.add_node(core.Pt(0.5, 0.25, 0.1), 0.08)
    want.add_beam(1, 0, 0, 0, 1)
    assert_region_is(rig, want, "0:2,0:2,0:2")
    assert bpy.ops.ple.beam_remove(index=0, rig=rig.name) == {"FINISHED"}
    want.remove_beam(0)
    assert_region_is(rig, want, "0:2,0:2,0:2")
    assert bpy.ops.ple.node_remove(index=0, rig=rig.name) == {"FINISHED"}
    want.remove_node(0)
    assert_region_is(rig, want, "0:2,0:2,0:2")
    assert ("node", 1) not in ple_ext.rig.model.parts(rig)
    fails(bpy.ops.ple.beam_remove, "beam-pattern 9", index=9, rig=rig.name)


def case_snippet_round_trip():
    """GUI edits -> Apply -> re-run the program text -> the same lattice within 1e-9."""
    text = bpy.data.texts.new("prog.py")
    text.from_string(PROGRAM)
    assert bpy.ops.ple.lattice_add(source="TEXT", text="prog.py") == {"FINISHED"}
    rig = bpy.context.active_object
    rig["ple:n"] = 4
    rig.update_tag()
    update()
    fu, fv = part(rig, "u"), part(rig, "v")
    fu.matrix_basis = bpy_matrix(core.Swirl(0.3, core.Vec(0, 0, 1), core.Pt(-2, 0, 0), 1.05).matrix @ matrix(fu))
    update()
    fv.rotation_euler = (0.1, 0.0, 0.2)
    update()
    rig.ple.counts = (4, 5, 3)
    assert bpy.ops.ple.node_add(center=(0.5, 0.5, 0.5), radius=0.05) == {"FINISHED"}
    assert bpy.ops.ple.beam_add(n1=0, n2=1, offset=(0, 0, 0)) == {"FINISHED"}
    gui = ple_ext.rig.model.lattice_of(rig)
    assert bpy.ops.ple.snippet_copy() == {"FINISHED"}
    clip = bpy.context.window_manager.clipboard
    snippet = bpy.data.texts["PLE snippet"].as_string()
    assert clip.strip() in ("", snippet.strip()), clip  # headless bpy has no system clipboard: reads ""
    assert "lat.set_u(4, Swirl(" in snippet and "lat.add_beam(0, 1, 0, 0, 0)" in snippet, snippet
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    new = text.as_string()
    assert "# the template node-group" in new and "# along U" in new
    rerun = core.compile_program(new).run(thickness=0.1, n=4)
    assert core.program.snippets.lattices_close(rerun, gui, 1e-9)
    assert rig.ple.edits == "[]" and core.program.snippets.lattices_close(ple_ext.rig.model.lattice_of(rig), gui, 1e-9)


def case_ir_apply():
    tmp = Path(tempfile.mkdtemp())
    core.io.irfile.save_ir(core.load_lattice("cubic", {"n": 3}), tmp / "c.json")
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(tmp / "c.json")) == {"FINISHED"}
    rig = bpy.context.active_object
    part(rig, "v").location = (0.1, 1.5, 0)
    update()
    gui = ple_ext.rig.model.lattice_of(rig)
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    again = core.model.ir.lattice_from_dict(json.loads(rig.ple.text.as_string()))
    assert core.program.snippets.lattices_close(again, gui, 1e-9)


def case_no_leaks():
    rig = new_rig("fig6_3", region=(3, 3, 3))
    fu = part(rig, "u")
    counts = lambda: (len(bpy.data.meshes), len(bpy.data.curves), len(bpy.data.objects),  # noqa: E731
                      len(bpy.data.node_groups), len(bpy.data.texts), len(bpy.data.collections))
    before = counts()
    start = fu.location.copy()
    for n in range(600):  # a leak of one datablock per update, or per count change (4 here), shows
        fu.location = (start[0] + 0.001 * (n % 50), start[1], start[2])
        if n % 150 == 75:
            rig.ple.counts = (7, 12, 10 + n % 3)
        update()
    assert counts() == before, (before, counts())
    assert len(ple_ext.rig.model.edits_of(rig)) <= 3  # coalesced


def case_errors():
    text = bpy.data.texts.new("broken.py")
    text.from_string("def lattice(:\n    pass\n")
    fails(bpy.ops.ple.lattice_add, "syntax error", source="TEXT", text="broken.py")
    assert bpy.data.texts["broken.py"].as_string() == "def lattice(:\n    pass\n"  # kept
    assert not [o for o in bpy.data.objects if o.name.startswith("broken")]
    fails(bpy.ops.ple.lattice_add, "x.py", source="FILE", filepath="/nonexistent/x.py")
    rig = new_rig("fig6_3")
    source = rig.ple.text.as_string()
    co0, _, _ = region_arrays(rig)
    fu = part(rig, "u")
    scale0 = fu.scale.copy()
    fu.scale = (1.0, 2.0, 1.0)  # a degenerate frame: not a similarity
    update()
    assert "frame U" in rig.ple.status
    co1, _, _ = region_arrays(rig)
    assert np.allclose(co0, co1, atol=1e-6) and rig.ple.text.as_string() == source
    assert bpy.ops.ple.snippet_copy() == {"FINISHED"}  # still usable
    fu.scale = scale0
    update()
    assert rig.ple.status == ""
    rig.ple.text.from_string(source.replace("lat.set_u(7", "lat.set_u(-7"))  # a program that raises
    fails(bpy.ops.ple.program_run, "count")
    assert "count" in rig.ple.status and "-7" in rig.ple.text.as_string()
    co2, _, _ = region_arrays(rig)
    assert np.allclose(co0, co2, atol=1e-6)  # last good drawing kept
    fails(bpy.ops.ple.stencil_filter, "stencil", shape=(2, 2, 2), bits="10")
    fails(bpy.ops.ple.export, "x.docx", filepath="/tmp/x.docx")
    assert not Path("/tmp/x.docx").exists()
    fails(bpy.ops.ple.lil_filter, "coarse")
    fails(bpy.ops.ple.lattice_add, "no text block", source="TEXT", text="nope")
    # a Blender without trimesh: Tessellate streams its boxes without it, an Export to GLB (trimesh
    # encodes it) reports the missing package, no traceback
    new_rig("cubic", region=(2, 2, 2))
    vendored = "bl_ext.user_default.ple.vendor.ple"
    saved = {k: sys.modules.pop(k) for k in list(sys.modules)
             if k == "trimesh" or k.startswith("trimesh.") or k in (f"{vendored}.meshing.tessellate",
                                                                   f"{vendored}.meshing.preview",
                                                                   f"{vendored}.app.pipeline")}
    sys.modules["trimesh"] = None
    try:
        assert bpy.ops.ple.tessellate(style="CNT") == {"FINISHED"}
        glb = Path(tempfile.mkdtemp()) / "x.glb"
        fails(bpy.ops.ple.export, "'trimesh'", filepath=str(glb))
        assert not glb.exists()
    finally:
        del sys.modules["trimesh"]
        sys.modules.update(saved)


def case_untrusted():
    """Programs in a file run only if Blender trusts scripts or the user ran them (SPEC §9)."""
    rig = new_rig("cubic")
    ple_ext.session.SESSION.trusted.clear()
    ple_ext.session.SESSION.forget_drawn()
    assert not bpy.context.preferences.filepaths.use_scripts_auto_execute
    rig["ple:n"] = 4
    rig.update_tag()
    update()
    assert "trust" in rig.ple.status and tuple(rig.ple.counts) == (10, 10, 10)
    assert bpy.ops.ple.program_run() == {"FINISHED"}
    assert tuple(rig.ple.counts) == (4, 4, 4) and rig.ple.status == ""


def case_undo():
    """Undo in background bpy: undo_push + ed.undo restores the frame and the edits; the
    undo_post handler redraws from the restored state (not read as a user move)."""
    rig = new_rig("cubic", region=(2, 2, 2))
    name = rig.name
    bpy.ops.ed.undo_push(message="before")
    co0, _, _ = region_arrays(rig)
    part(rig, "u").location = (2.0, 0, 0)
    update()
    bpy.ops.ed.undo_push(message="moved")
    assert not np.allclose(region_arrays(rig)[0], co0)
    assert bpy.ops.ed.undo() == {"FINISHED"}
    rig = bpy.data.objects[name]
    assert ple_ext.rig.model.edits_of(rig) == []
    assert np.allclose(region_arrays(rig)[0], co0)
    update()
    assert ple_ext.rig.model.edits_of(rig) == []
    # an operator's step (bpy pushes it itself only in the UI: here we push it as the UI would)
    assert bpy.ops.ple.node_add(rig=name, center=(0.5, 0.5, 0), radius=0.05) == {"FINISHED"}
    bpy.ops.ed.undo_push(message="Add Template Node")
    assert len(region_arrays(bpy.data.objects[name])[0]) == 16
    assert bpy.ops.ed.undo() == {"FINISHED"}
    rig = bpy.data.objects[name]
    assert len(region_arrays(rig)[0]) == 8 and ("node", 1) not in ple_ext.rig.model.parts(rig)
    assert bpy.ops.ed.redo() == {"FINISHED"}
    rig = bpy.data.objects[name]
    assert len(region_arrays(rig)[0]) == 16 and len(ple_ext.rig.model.lattice_of(rig).nodes) == 2


def case_filters():
    fine = new_rig("cubic", region=(10, 10, 10))
    coarse = new_rig("fig6_3")
    coarse.location = (2, 2, 0)
    update()
    assert bpy.ops.ple.lil_filter(rig=fine.name, coarse=coarse.name) == {"FINISHED"}
    lat_f, lat_c = core.load_lattice("cubic"), core.load_lattice("fig6_3")
    placed = lat_c.copy()
    placed.set_placement(core.Translation(core.Vec(2, 2, 0)) @ lat_c.placement)
    want = core.filters.lil(lat_f, placed).evaluate("0:10,0:10,0:10")
    co, _, ed = region_arrays(fine)
    assert len(co) == len(want.center) and 0 < len(co) < 1000
    assert np.allclose(co, want.center, atol=1e-5) and np.array_equal(ed, want.beam_nodes)
    medium = new_rig("cubic")  # a cascade: fine in (medium in coarse), thesis Fig. 9.3
    medium["ple:cell"] = 0.5
    medium.location = (1, 1, 0)
    medium.update_tag()
    update()
    assert bpy.ops.ple.lil_filter(rig=medium.name, coarse=coarse.name) == {"FINISHED"}
    assert bpy.ops.ple.lil_filter(rig=fine.name, coarse=medium.name) == {"FINISHED"}
    lat_m = core.load_lattice("cubic", {"cell": 0.5})
    lat_m.set_placement(core.Translation(core.Vec(1, 1, 0)))
    want = core.filters.lil(lat_f, lat_m, placed).evaluate("0:10,0:10,0:10")
    co, _, _ = region_arrays(fine)
    assert len(co) == len(want.center) and np.allclose(co, want.center, atol=1e-5)
    fails(bpy.ops.ple.lil_filter, "cycle", rig=coarse.name, coarse=fine.name)
    assert coarse.ple.filter_kind == "NONE" and "cycle" in coarse.ple.status  # not kept; the panel says why
    assert bpy.ops.ple.stencil_filter(rig=fine.name, shape=(2, 1, 1), bits="10") == {"FINISHED"}
    co, _, _ = region_arrays(fine)
    assert len(co) == 500 and np.allclose(np.round(co[:, 0]) % 2, 0)
    assert bpy.ops.ple.stencil_filter(rig=fine.name, clear=True) == {"FINISHED"}
    assert len(region_arrays(fine)[0]) == 1000
    prog = new_rig("hier_stencil", region=(4, 4, 4))  # a filter set by the program itself
    lat = core.load_lattice("hier_stencil")
    want = core.filters.FilteredLattice(lat, lat.filter).evaluate("0:4,0:4,0:4")
    co, _, ed = region_arrays(prog)
    assert 0 < len(co) == len(want.center) < 64 * len(lat.nodes) and np.array_equal(ed, want.beam_nodes)


def case_tessellate():
    rig = new_rig("cubic", region=(2, 2, 2))
    before = len(bpy.data.meshes)
    from ple.meshing.tessellate import tessellate

    lat = core.load_lattice("cubic")
    for style in ("CHOCC", "CNT"):
        assert bpy.ops.ple.tessellate(style=style) == {"FINISHED"}
        me = bpy.data.objects[f"{rig.name}.{style.lower()}"].data
        want = tessellate(lat, "0:2,0:2,0:2", style.lower())
        assert (len(me.vertices), len(me.polygons)) == (len(want.vertices), len(want.faces))
        assert len(me.edges) * 2 == 3 * len(me.polygons)  # closed: every edge in two triangles
        co = np.zeros(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", co)
        from scipy.spatial import cKDTree  # built box by box: the same vertices in another order

        got_v, want_v = co.reshape(-1, 3), np.asarray(want.vertices)
        assert cKDTree(want_v).query(got_v)[0].max() < 1e-5 and cKDTree(got_v).query(want_v)[0].max() < 1e-5
    assert len(bpy.data.meshes) == before + 2


def case_export():
    import trimesh

    rig = new_rig("cubic", region=(3, 3, 2))
    lat = core.load_lattice("cubic")
    tmp = Path(tempfile.mkdtemp())
    assert bpy.ops.ple.export(filepath=str(tmp / "r.stl"), style="BALLS_BEAMS") == {"FINISHED"}
    mesh = trimesh.load(tmp / "r.stl")
    ev = lat.evaluate("0:3,0:3,0:2")
    want = core.meshing.preview.balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes)
    assert len(mesh.faces) == len(want.faces)
    assert np.allclose(mesh.bounds, want.bounds, atol=1e-5)
    from ple.meshing.tessellate import tessellate

    exact = tessellate(lat, "0:3,0:3,0:2", "chocc")
    assert bpy.ops.ple.export(filepath=str(tmp / "c.stl"), style="CHOCC") == {"FINISHED"}  # streamed by box
    got = trimesh.load(tmp / "c.stl")
    assert len(got.faces) == len(exact.faces) and got.is_watertight
    assert np.isclose(got.volume, exact.volume, rtol=1e-5)
    assert bpy.ops.ple.export(filepath=str(tmp / "c.ply"), style="CNT") == {"FINISHED"}
    assert len(trimesh.load(tmp / "c.ply").faces) == len(tessellate(lat, "0:3,0:3,0:2", "cnt").faces)
    assert rig.ple.status == "" and sorted(p.name for p in tmp.iterdir() if p.name.startswith(".")) == []
    # Esc in the modal run closes the step generator, which stops the child: nothing is written
    op = type("Op", (), {"filepath": str(tmp / "cancelled.stl"), "style": "CHOCC", "beyond_limit": False,
                         "report": print, "file_job": ple_ext.ops.base.SteppedOperator.file_job,
                         "subject": ple_ext.ops.output.MeshOperator.subject})()
    steps = bpy.types.PLE_OT_export.steps(op, bpy.context, rig)
    first, second = next(steps), next(steps)
    assert first == 0.0 and 0.0 <= second < 1.0  # progress of the first boxes
    steps.close()
    assert not (tmp / "cancelled.stl").exists() and not list(tmp.glob(".cancelled*"))
    # Esc after the child wrote its whole file, before Blender took the result: still nothing
    (tmp / "kept.stl").write_bytes(b"the user's file")
    op.filepath = str(tmp / "kept.stl")
    steps = bpy.types.PLE_OT_export.steps(op, bpy.context, rig)
    next(steps), next(steps)
    time.sleep(3.0)  # a 3x3x2 CHoCC export is done in well under a second
    steps.close()
    assert (tmp / "kept.stl").read_bytes() == b"the user's file"
    assert sorted(p.name for p in tmp.iterdir()) == ["c.ply", "c.stl", "kept.stl", "r.stl"], list(tmp.iterdir())


def case_ui():
    panels = [c for c in bpy.types.Panel.__subclasses__() if getattr(c, "bl_category", "") == "PLE"]
    labels = {c.bl_label for c in panels}
    assert labels == {"Program", "Frames", "Region", "Template", "Filters", "Body", "Tessellate & Export",
                      "CLG", "Möbius Frames", "Check"}
    assert all(c.bl_space_type == "VIEW_3D" and c.bl_region_type == "UI" for c in panels)
    desc = bpy.types.PLE_OT_stencil_filter.__doc__ + bpy.types.PLE_OT_beam_add.__doc__
    assert "stencil" in desc and "beam-pattern" in desc
    rig = new_rig("fig6_3")  # draw every panel into a recording layout that checks each reference
    rig.ple.filter_kind = "STENCIL"
    seen = []
    for cls in panels:
        if cls.poll(bpy.context):
            cls.draw(type("P", (), {"layout": CheckedLayout(seen), "rig": cls.rig})(), bpy.context)
    assert {"ple.lattice_add", "ple.program_run", "ple.program_apply", "ple.snippet_copy", "ple.node_add",
            "ple.beam_add", "ple.beam_remove", "ple.lil_filter", "ple.stencil_filter", "ple.tessellate",
            "ple.export"} <= set(seen)
    assert "ple:thickness" in seen and "stencil_bits" in seen


class CheckedLayout:
    """A stand-in for bpy's UILayout (headless bpy cannot draw): checks that every property
    and operator a panel references exists, and records them."""

    def __init__(self, seen):
        self.seen = seen

    def row(self, **kw):
        return self

    column = row

    def label(self, **kw):
        assert isinstance(kw.get("text", ""), str)

    def separator(self, **kw):
        pass

    def prop(self, data, name, **kw):
        if name.startswith('["'):
            assert name[2:-2] in data.keys(), name
            name = name[2:-2]
        else:
            assert name in data.bl_rna.properties, name
        self.seen.append(name)

    def operator(self, idname, **kw):
        mod, op = idname.split(".")
        assert hasattr(getattr(bpy.ops, mod), op), idname
        self.seen.append(idname)
        return type("OpProps", (), {})()


def case_becots_corners():
    rig = new_rig("becots_kagome")
    lat = core.load_lattice("becots_kagome")
    corners = lat.becots.to_ir()["corners"]
    p = ple_ext.rig.model.parts(rig)
    for label, c in zip("ABCD", corners):
        assert np.allclose(matrix(p[("corner", label)])[:3, 3], c, atol=1e-5)
    rig.ple.region_min, rig.ple.region_max = (0, 0, 0), (3, 3, lat.counts[2])
    p[("corner", "C")].location = (4.0, 6.5, -2.0)  # drag corner C: the slab follows (set_becots)
    update()
    assert rig.ple.status == "", rig.ple.status
    moved = [tuple(matrix(p[("corner", c)])[:3, 3]) for c in "ABCD"]
    want = lat.copy()
    want.set_becots(*moved, counts=tuple(lat.becots.counts))
    assert_region_is(rig, want, f"0:3,0:3,0:{lat.counts[2]}")
    assert bpy.ops.ple.snippet_copy() == {"FINISHED"}
    assert "lat.set_becots(Pt(" in bpy.data.texts["PLE snippet"].as_string()
    good = rig.ple.edits
    p[("corner", "B")].location = p[("corner", "A")].location  # coincident corners: refused, not stored
    update()
    assert "coincide" in rig.ple.status and rig.ple.edits == good, (rig.ple.status, good, rig.ple.edits)
