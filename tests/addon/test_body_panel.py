"""The Body panel of the extension, installed from the built zip into headless bpy 5.0.1.

The cases run in the test run's one Blender worker (``conftest.py``). Truth is the core package of
the environment (an independent copy of the vendored one) on the same mesh, built here with trimesh
and placed by trimesh (the add-on reads it back from Blender with ``foreach_get`` and places it by
the object's transform).
"""

from __future__ import annotations

import numpy as np
import pytest
import test_addon as base

CASES = ["fill_modes", "grade_empties", "cleanup_skin_tessellate", "live_move", "bad_bodies", "ui",
         "skin_solid_no_coincident_vertices"]
TURN = (0.3, -0.2, 0.5)  # the body object's rotation (XYZ Euler)


@pytest.mark.parametrize("case", CASES)
def test_body_panel(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
def part_mesh():
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=2)
    mesh.apply_scale([2.2, 1.6, 1.3])  # an ellipsoid, non-uniform in its own coordinates
    return mesh


def body_object(name="part", location=(4.6, 4.4, 4.5), scale=1.1):
    """A Blender mesh object holding ``part_mesh`` placed by a rotation, uniform scale, location."""
    bpy = base.bpy
    mesh = part_mesh()
    me = bpy.data.meshes.new(name)
    me.from_pydata(mesh.vertices.tolist(), [], mesh.faces.tolist())
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler, obj.scale = location, TURN, (scale, scale, scale)
    base.update()
    return obj


def truth_body(obj):
    """The core's Body of the same mesh, placed by trimesh with the object's world matrix."""
    import ple.filters.body  # noqa: F401 - the environment's core, for the truth
    import ple.io.bodyfile  # noqa: F401

    mesh = part_mesh()
    mesh.apply_transform(np.array(obj.matrix_world, dtype=float))
    return base.core.io.bodyfile.body_from_trimesh(mesh)


def kept(lat, body, mode, region):
    return lat.with_filter(base.core.filters.body.BodyFilter(body, mode)).evaluate(region)


def fill(rig, obj, **kw):
    return base.bpy.ops.ple.body_fill(rig=rig.name, body=obj.name if obj else "", **kw)


def case_fill_modes():
    rig = base.new_rig("cubic", region=(10, 10, 10))
    obj = body_object()
    lat = base.core.load_lattice("cubic")
    body = truth_body(obj)
    counts = {}
    for mode in ("INSIDE", "CENTROID", "ANY"):
        assert fill(rig, obj, fill=mode) == {"FINISHED"}, mode
        want = kept(lat, body, mode.lower(), "0:10,0:10,0:10")
        co, rad, ed = base.region_arrays(rig)
        assert 0 < len(co) == len(want.center) < 1000, (mode, len(co), len(want.center))
        assert np.allclose(co, want.center, atol=1e-5) and np.array_equal(ed, want.beam_nodes)
        counts[mode] = len(co)
    assert counts["INSIDE"] < counts["ANY"]
    assert fill(rig, None) == {"FINISHED"}  # clearing the body draws every node again
    assert len(base.region_arrays(rig)[0]) == 1000


def case_grade_empties():
    import ple.model.grading  # noqa: F401

    bpy = base.bpy
    rig = base.new_rig("cubic", region=(10, 10, 10))
    a, b = (bpy.data.objects.new(n, None) for n in ("A", "B"))
    for e, loc in ((a, (0, 0, 0)), (b, (9, 9, 9))):
        bpy.context.scene.collection.objects.link(e)
        e.location = loc
    s = rig.ple_body
    s.grade_a, s.grade_b, s.factor_a, s.factor_b = a, b, 1.0, 2.0
    s.grade = "LINEAR"
    base.update()
    assert rig.ple.status == "", rig.ple.status
    lat = base.core.load_lattice("cubic")
    _, rad, _ = base.region_arrays(rig)
    ev = lat.evaluate("0:10,0:10,0:10")
    t = np.clip(ev.center @ np.ones(3) / 27.0, 0, 1)
    assert np.allclose(rad, ev.radius * (1 + t), rtol=1e-6)  # r at A to 2r at B (float32 attribute)
    assert rad.max() == pytest.approx(2 * ev.radius.max(), rel=1e-6)
    b.location = (9, 0, 0)  # moving an empty redraws: the gradient now runs along x only
    base.update()
    _, rad, _ = base.region_arrays(rig)
    assert np.allclose(rad, ev.radius * (1 + ev.center[:, 0] / 9.0), rtol=1e-6)


def case_cleanup_skin_tessellate():
    import ple.filters.cleanup  # noqa: F401
    import ple.meshing.skin  # noqa: F401
    import ple.meshing.tessellate  # noqa: F401
    import trimesh

    bpy = base.bpy
    rig = base.new_rig("cubic", region=(10, 10, 10))
    obj = body_object()
    assert fill(rig, obj, fill="ANY", cleanup=True, skin=0.3) == {"FINISHED"}
    lat = base.core.load_lattice("cubic").with_filter(base.core.filters.body.BodyFilter(truth_body(obj), "any"))
    cleaned, report = base.core.filters.cleanup.cleanup(lat, "0:10,0:10,0:10", skin=0.3)
    want = cleaned.evaluate("0:10,0:10,0:10")
    co, _, ed = base.region_arrays(rig)
    assert report.anchored > 0 and len(co) == len(want.center) and np.array_equal(ed, want.beam_nodes)
    assert np.allclose(co, want.center, atol=1e-5)
    assert bpy.ops.ple.tessellate(style="CNT") == {"FINISHED"}  # cut at the body's surface (any)
    me = bpy.data.objects[f"{rig.name}.cnt"].data
    mesh = base.core.meshing.tessellate.tessellate(cleaned, "0:10,0:10,0:10", "cnt")
    assert len(me.polygons) == len(mesh.faces) and len(me.edges) * 2 == 3 * len(me.polygons)  # closed
    assert bpy.ops.ple.skin_solid() == {"FINISHED"}
    me = bpy.data.objects[f"{rig.name}.skin"].data
    solid = base.core.meshing.skin.skin(truth_body(obj), 0.3,
                                        base.core.meshing.tessellate.tessellate(cleaned, "0:10,0:10,0:10",
                                                                                               cut=False))
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    tri = np.zeros(len(me.polygons) * 3, np.int32)
    me.polygons.foreach_get("vertices", tri)
    got = trimesh.Trimesh(co.reshape(-1, 3), tri.reshape(-1, 3), process=False)
    # the add-on's body is read back from float32 Blender data: the Booleans' triangles differ
    # slightly from the truth's, the solid does not
    assert got.is_watertight and len(got.faces) == pytest.approx(len(solid.faces), rel=0.01)
    assert got.volume == pytest.approx(solid.volume, rel=1e-3)


def case_live_move():
    rig = base.new_rig("cubic", region=(10, 10, 10))
    obj = body_object()
    assert fill(rig, obj, fill="INSIDE") == {"FINISHED"}
    before = base.region_arrays(rig)[0]
    obj.location = (3.1, 4.4, 4.5)  # drag the body: the region follows (depsgraph handler)
    base.update()
    lat = base.core.load_lattice("cubic")
    want = kept(lat, truth_body(obj), "inside", "0:10,0:10,0:10")
    co = base.region_arrays(rig)[0]
    assert len(co) == len(want.center) and np.allclose(co, want.center, atol=1e-5)
    assert not (len(co) == len(before) and np.allclose(co, before))
    obj.data.vertices[0].co = (9.0, 0.0, 0.0)  # edit the mesh: a spike; the kept set follows it
    obj.data.update()
    base.update()
    assert rig.ple.status == "", rig.ple.status
    mesh = part_mesh()
    mesh.vertices[0] = (9.0, 0.0, 0.0)
    mesh.apply_transform(np.array(obj.matrix_world, dtype=float))
    want = kept(lat, base.core.io.bodyfile.body_from_trimesh(mesh), "inside", "0:10,0:10,0:10")
    assert len(base.region_arrays(rig)[0]) == len(want.center)


def case_bad_bodies():
    bpy = base.bpy
    rig = base.new_rig("cubic", region=(4, 4, 4))
    me = bpy.data.meshes.new("open")
    me.from_pydata([(0, 0, 0), (3, 0, 0), (0, 3, 0)], [], [(0, 1, 2)])
    plane = bpy.data.objects.new("open", me)
    bpy.context.scene.collection.objects.link(plane)
    base.fails(bpy.ops.ple.body_fill, "not closed", rig=rig.name, body="open")
    assert rig.ple_body.body is None and len(base.region_arrays(rig)[0]) == 64  # settings came back
    me = bpy.data.meshes.new("nan")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0), (float("nan"), 0, 1)], [], [(0, 1, 2), (0, 3, 1),
                                                                                (1, 3, 2), (2, 3, 0)])
    bad = bpy.data.objects.new("nan", me)
    bpy.context.scene.collection.objects.link(bad)
    base.fails(bpy.ops.ple.body_fill, "NaN", rig=rig.name, body="nan")
    base.fails(bpy.ops.ple.skin_solid, "Skin", rig=rig.name)


def case_ui():
    panels = [c for c in base.bpy.types.Panel.__subclasses__() if getattr(c, "bl_category", "") == "PLE"]
    body_panel = next(c for c in panels if c.bl_label == "Body")
    rig = base.new_rig("cubic")
    rig.ple_body.grade = "LINEAR"
    seen = []
    assert body_panel.poll(base.bpy.context)
    body_panel.draw(type("P", (), {"layout": base.CheckedLayout(seen), "rig": body_panel.rig})(), base.bpy.context)
    assert {"body", "fill", "skin", "cleanup", "keep_skin", "grade", "grade_a", "grade_b", "factor_a",
            "ple.skin_solid"} <= set(seen)
    assert "UNDO" in base.bpy.types.PLE_OT_body_fill.bl_options


def case_skin_solid_no_coincident_vertices():
    """Skin Solid's mesh has no two vertices at one position, so merging by position (an STL round
    trip, a slicer) keeps it watertight."""
    import trimesh

    bpy = base.bpy
    rig = base.new_rig("cubic", region=(10, 10, 10))
    obj = body_object()
    assert fill(rig, obj, fill="ANY", cleanup=True, skin=0.3) == {"FINISHED"}
    assert bpy.ops.ple.skin_solid() == {"FINISHED"}
    me = bpy.data.objects[f"{rig.name}.skin"].data
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    tri = np.zeros(len(me.polygons) * 3, np.int32)
    me.polygons.foreach_get("vertices", tri)
    assert len(np.unique(co, axis=0)) == len(co), len(co) - len(np.unique(co, axis=0))
    merged = trimesh.Trimesh(co, tri.reshape(-1, 3), process=False)
    merged.merge_vertices()
    assert merged.is_watertight and merged.is_winding_consistent
