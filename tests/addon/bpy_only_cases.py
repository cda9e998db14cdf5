"""Cases run in a Blender whose Python has only Blender's own packages (``test_bpy_only.py``): no
scipy, manifold3d, rtree or trimesh but the wheels the zip carries, and no ``ple`` but the
vendored one. This module imports nothing beyond the standard library and numpy (Blender's own);
each case writes what it made into its folder, and the pytest side checks it against the
project's core, an independent process with its own packages."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

bpy = ple_ext = core = None  # bound by the worker (core is None here)

SHRUNK = '''
def lattice():
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.12)
    b = lat.add_node(Pt(0.2, 0, 0), 0.12)
    lat.add_beam(a, b, 0, 0, 0)
    lat.add_beam(b, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 0, 0, 1)
    lat.set_u(4, Scaling(1.025, Pt(-16, 0, 0)))
    lat.set_v(3, Translation(Vec(0, 0.4, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 0.4)))
    return lat
'''

CROSSING = '''
def lattice():
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.13)
    for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0)):
        lat.add_beam(a, a, *d)
    lat.set_u(4, Translation(Vec(1, 0, 0)))
    lat.set_v(4, Rotation(0.025, Vec(0, 0, 1), Pt(0, -40, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 1)))
    return lat
'''


def save(name: str, data) -> None:
    (Path.cwd() / name).write_text(json.dumps(data))


def rig_from_text(name: str, source: str, region=(3, 3, 3)):
    text = bpy.data.texts.new(name)
    text.from_string(source)
    (Path.cwd() / name).write_text(source)
    assert bpy.ops.ple.lattice_add(source="TEXT", text=name, region=region) == {"FINISHED"}
    return bpy.context.active_object


def preset_rig(name: str, region=(3, 3, 3)):
    assert bpy.ops.ple.lattice_add(source="PRESET", preset=name, region=region) == {"FINISHED"}
    return bpy.context.active_object


def drawn(rig) -> int:
    part = ple_ext.rig.model.parts(rig).get("region")
    return len(part.data.vertices) if part is not None else 0


def mesh_object_faces(name: str) -> int:
    return len(bpy.data.objects[name].data.polygons)


def case_wheels_from_the_zip():
    """The packages the core needs come from the zip's wheels, not from any other Python."""
    import importlib

    where = {}
    for name in ("scipy", "manifold3d", "rtree", "trimesh"):
        where[name] = str(Path(importlib.import_module(name).__file__).resolve())
    import sys

    where["ple"] = str(Path(sys.modules[ple_ext.__name__ + ".vendor.ple"].__file__).resolve())
    for name in json.loads((Path.cwd() / "compiled.json").read_text()):  # the core's C modules, by the test
        where[name] = str(Path(importlib.import_module(f"{ple_ext.__name__}.vendor.{name}").__file__).resolve())
    save("modules.json", where)


def case_unclean_export_and_tessellate():
    rig = rig_from_text("crossing.py", CROSSING)
    assert bpy.ops.ple.export(filepath=str(Path.cwd() / "crossing.stl"), style="CNT") == {"FINISHED"}
    assert "unclean" in rig.ple.status, rig.ple.status
    bpy.context.view_layer.update()  # the status stays until the user's next edit
    assert "unclean" in rig.ple.status, rig.ple.status
    rig.ple.status = ""
    assert bpy.ops.ple.tessellate(style="CNT") == {"FINISHED"}
    bpy.context.view_layer.update()
    region = str(ple_ext.rig.model.region_of(rig, ple_ext.rig.model.shown_lattice(rig)))
    save("crossing.json", {"region": region, "faces": mesh_object_faces(f"{rig.name}.cnt"), "status": rig.ple.status})


def ellipsoid(name="part", location=(4.6, 4.4, 4.5)):
    """A closed mesh object: a UV sphere scaled into an ellipsoid (Blender's own primitive)."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=1.0, location=location)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = (2.4, 1.8, 1.5)
    bpy.context.view_layer.update()
    return obj


def world_triangles(obj) -> list:
    me = obj.data
    me.calc_loop_triangles()
    m = np.array(obj.matrix_world)
    co = np.array([(m @ np.array([*v.co, 1.0]))[:3] for v in me.vertices])
    tris = np.array([t.vertices[:] for t in me.loop_triangles])
    return [co.tolist(), tris.tolist()]


def case_body_fill_and_skin():
    rig = preset_rig("cubic", region=(10, 10, 10))
    body = ellipsoid()
    save("body.json", world_triangles(body))
    assert bpy.ops.ple.body_fill(rig=rig.name, body=body.name, fill="INSIDE") == {"FINISHED"}
    inside = drawn(rig)
    assert bpy.ops.ple.body_fill(rig=rig.name, body=body.name, fill="ANY", cleanup=True, skin=0.3) == {"FINISHED"}
    bpy.context.view_layer.objects.active = rig
    assert bpy.ops.ple.tessellate(style="CNT") == {"FINISHED"}
    assert bpy.ops.ple.skin_solid() == {"FINISHED"}
    skin = bpy.data.objects[f"{rig.name}.skin"].data
    save("fill.json", {"inside": inside, "any_cleaned": drawn(rig), "cut_faces": mesh_object_faces(f"{rig.name}.cnt"),
                       "skin_faces": len(skin.polygons), "skin_edges": len(skin.edges)})


def case_lil_on_a_curved_lattice():
    fine = preset_rig("cylindrical", region=(6, 6, 2))
    coarse = preset_rig("fig6_3")
    assert bpy.ops.ple.lil_filter(rig=fine.name, coarse=coarse.name) == {"FINISHED"}
    save("lil.json", {"kept": drawn(fine), "message": fine.ple.message})


def case_check():
    rig = rig_from_text("check.py", CROSSING)
    rig.ple_check.min_feature = 0.2
    assert bpy.ops.ple.check() == {"FINISHED"}
    save("check.json", json.loads(rig.ple_check.report))


def case_clg_preview():
    assert bpy.ops.ple.clg_add(source="PRESET", preset="plate", region=(1, 1, 1)) == {"FINISHED"}
    rig = bpy.context.active_object
    assert bpy.ops.ple.clg_preview() == {"FINISHED"}
    me = ple_ext.rig.model.parts(rig)["clg"].data
    save("clg.json", {"vertices": len(me.vertices), "polygons": len(me.polygons), "status": rig.ple_clg.status})


def case_every_preset():
    """Every preset of the Add menu added, tessellated and exported with its defaults (those of
    them that ``shard.json`` names, when the test wrote one)."""
    out = {}
    asked = Path.cwd() / "shard.json"
    names = json.loads(asked.read_text()) if asked.exists() else ple_ext.corelink.presets.preset_names()
    for name in names:
        t = [time.perf_counter()]
        assert bpy.ops.ple.lattice_add(source="PRESET", preset=name) == {"FINISHED"}, name
        rig = bpy.context.active_object
        before = {o.name for o in bpy.data.objects}
        t.append(time.perf_counter())
        assert bpy.ops.ple.tessellate() == {"FINISHED"}, name
        made = [bpy.data.objects[n] for n in {o.name for o in bpy.data.objects} - before]
        assert len(made) == 1 and len(made[0].data.polygons) > 0, name
        t.append(time.perf_counter())
        assert bpy.ops.ple.export(rig=rig.name, filepath=str(Path.cwd() / f"{name}.stl")) == {"FINISHED"}, name
        t.append(time.perf_counter())
        out[name] = {"tessellated": len(made[0].data.polygons), "status": rig.ple.status,
                     "seconds": [round(b - a, 2) for a, b in zip(t[:-1], t[1:])]}  # add, tessellate, export
        bpy.ops.wm.read_homefile(use_empty=True)  # the next preset in an empty scene
    save("presets.json", out)


def case_same_triangles_every_door():
    """The add-on's Export of clean, unclean (crossing, shrunk), stencil-filtered (an IR file the
    test wrote), Möbius and body-cut lattices; the test runs ple mesh on the same sources and
    regions and compares the files."""
    out = []

    def export(label, rig, source, style="CNT", whole=False):
        model = ple_ext.rig.model
        region = None if whole else str(model.region_of(rig, model.shown_lattice(rig)))
        assert bpy.ops.ple.export(rig=rig.name, filepath=str(Path.cwd() / f"{label}.stl"), style=style) == {"FINISHED"}
        bpy.context.view_layer.update()  # a redraw: the unclean line stays the rig's status until the next edit
        out.append({"label": label, "source": source, "region": region, "style": style.lower(),
                    "status": rig.ple.status})

    export("clean", preset_rig("cubic"), "cubic")
    export("crossing", rig_from_text("crossing.py", CROSSING), "crossing.py")
    shrunk = rig_from_text("shrunk.py", SHRUNK)
    export("shrunk", shrunk, "shrunk.py")
    export("shrunk_chocc", shrunk, "shrunk.py", "CHOCC")
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(Path.cwd() / "stencil.json")) == {"FINISHED"}
    export("filtered", bpy.context.active_object, "stencil.json")
    export("mobius", preset_rig("mobius_slab"), "mobius_slab", whole=True)
    export("bracket", preset_rig("bracket_fill"), "bracket_fill")
    save("doors.json", out)
