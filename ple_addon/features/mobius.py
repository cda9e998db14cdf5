"""Möbius lattices in Blender (thesis §11.3): their control frames as empties the user drags.

A Möbius rig is an empty holding a Möbius lattice preset (``mobius_slab``, ``tmi_slab``, or any
preset whose lattice is placed by Möbius transformations) with, per control frame X, Y, Z (W),
an ARROWS empty (origin A, x axis to B: the similarity part of the Möbius frame {A, B, C}) and a
sphere handle for C (a child of the frame: a similarity frame has it on the y axis; moving it
bends the frame), plus the region (balls and beams by the shared geometry-nodes modifier).
Moving a frame or a handle and updating the depsgraph rebuilds the lattice from the frames
(``ple.model.mobius.with_control_frames``) and redraws it. Everything geometric is the core's:
this module only reads matrices and writes the core's node positions.

Custom properties mark the objects (so the steady-lattice rig code never sees them):
``ple_mobius`` (the rig: preset name), ``ple_mobius_frame`` / ``ple_mobius_handle`` (a frame
name), ``ple_mobius_region``.
"""

from __future__ import annotations

import json

import bpy
import numpy as np
from mathutils import Matrix

from .. import draw
from ..corelink import PleError, core, presets
from ..ops.base import SNIPPET_TEXT, RigPanel
from ..rig import hooks
from ..session import SESSION

mobius = core("model.mobius")
sources = core("program.sources")

PRESETS = ("mobius_slab", "tmi_slab")  # the shipped Möbius presets: Add › PLE Lattice › NAME routes here
MAX_NODES = 200_000  # a region larger than this is not drawn live
MOVE_DIGITS = 7  # matrices compared at this many decimals (float32 frames)


def is_mobius_rig(obj) -> bool:
    return obj is not None and "ple_mobius" in obj


def rig_of(obj):
    """The Möbius rig an object belongs to (itself, a frame, a handle or the region), or None."""
    while obj is not None:
        if is_mobius_rig(obj):
            return obj
        obj = obj.parent
    return None


def parts(rig) -> dict:
    """{"X": frame, ("handle", "X"): handle, "region": mesh object} of a rig."""
    out = {}
    for obj in rig.children_recursive:
        if "ple_mobius_frame" in obj:
            out[obj["ple_mobius_frame"]] = obj
        elif "ple_mobius_handle" in obj:
            out[("handle", obj["ple_mobius_handle"])] = obj
        elif "ple_mobius_region" in obj:
            out["region"] = obj
    return out


def _new_object(rig, name: str, data, parent):
    obj = bpy.data.objects.new(name, data)
    for coll in rig.users_collection:
        coll.objects.link(obj)
    obj.parent = parent
    obj.matrix_parent_inverse = Matrix.Identity(4)
    return obj


def drawn() -> dict:
    """Rig name -> (preset, params, base lattice, signature last drawn)."""
    return SESSION.cache("mobius")


def base_lattice(rig):
    """The preset's lattice with the rig's parameters (cached per rig)."""
    name, params = rig["ple_mobius"], json.loads(rig.get("ple_mobius_params", "{}"))
    hit = drawn().get(rig.name)
    if hit is not None and hit[0] == name and hit[1] == params:
        return hit[2]
    if name not in presets.preset_names():
        raise PleError(f"Möbius rig: unknown preset {name!r}")
    lat = sources.load_lattice(name, params)
    mobius.control_frames(lat)  # a PleError if it is not a Möbius lattice
    if lat.node_count() > MAX_NODES:
        raise PleError(f"{name}: {lat.node_count():,} nodes are more than {MAX_NODES:,} to draw live")
    drawn()[rig.name] = (name, params, lat, ())
    return lat


def frames_of(rig) -> dict:
    """The Möbius frames {A, B, C} the rig's empties show, in the rig's coordinates."""
    p = parts(rig)
    out = {}
    for key, obj in p.items():
        if isinstance(key, str) and key != "region":
            handle = p.get(("handle", key))
            h = np.array(handle.matrix_basis.translation) if handle is not None else np.array([0.0, 1.0, 0.0])
            out[key] = mobius.frame_from_handles(np.array(obj.matrix_basis), h)
    return out


def _signature(rig) -> tuple:
    return tuple(sorted((str(k), tuple(np.round(np.array(o.matrix_basis), MOVE_DIGITS).ravel()))
                        for k, o in parts(rig).items() if k != "region"))


def refresh(rig, force: bool = False) -> str | None:
    """Rebuild and redraw the lattice if a frame or handle moved; returns an error or None (the
    last good drawing stays, the error is the rig's ``ple_status``)."""
    sig = _signature(rig)
    hit = drawn().get(rig.name)
    if not force and hit is not None and hit[3] == sig:
        if rig.get("ple_status"):  # a degenerate frame was put back where it was: nothing is wrong now
            rig["ple_status"] = ""
        return None
    try:
        base = base_lattice(rig)
        lat = mobius.with_control_frames(base, frames_of(rig))
        ev = lat.evaluate()
    except PleError as exc:
        rig["ple_status"] = str(exc)
        return str(exc)
    region = parts(rig).get("region")
    if region is not None:
        draw.region_mesh(region.data, ev)
    name, params, _, _ = drawn()[rig.name]
    drawn()[rig.name] = (name, params, base, sig)
    rig["ple_status"] = ""
    return None


def create(context, preset: str, params: dict | None = None):
    """A Möbius rig for ``preset`` at the 3D cursor: frames, handles and the region."""
    if preset not in presets.preset_names():
        raise PleError(f"unknown preset {preset!r}")
    lat = sources.load_lattice(preset, params or {})
    frames = mobius.control_frames(lat)
    rig = bpy.data.objects.new(f"PLE {preset}", None)
    context.collection.objects.link(rig)
    rig.empty_display_type = "PLAIN_AXES"
    rig.location = context.scene.cursor.location
    rig["ple_mobius"], rig["ple_mobius_params"] = preset, json.dumps(params or {})
    for key, frame in frames.items():
        m, h = mobius.frame_handles(frame)
        f = _new_object(rig, f"{rig.name}.{key}", None, rig)
        f.empty_display_type, f.empty_display_size = "ARROWS", 1.0
        f["ple_mobius_frame"] = key
        f.matrix_basis = Matrix(m.tolist())
        hd = _new_object(rig, f"{rig.name}.{key}.C", None, f)
        hd.empty_display_type, hd.empty_display_size = "SPHERE", 0.15
        hd["ple_mobius_handle"] = key
        hd.location = h.tolist()
    region = _new_object(rig, f"{rig.name}.region", draw.new_region_mesh(f"{rig.name}.region"), rig)
    region["ple_mobius_region"] = True
    region.hide_select = True
    draw.add_balls_beams_modifier(region)
    draw.set_material(region, draw.REGION_MATERIAL)
    drawn().pop(rig.name, None)
    error = refresh(rig, force=True)
    if error:
        bpy.data.batch_remove([rig, *rig.children_recursive])
        raise PleError(error)
    return rig


class PLE_OT_mobius_add(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a Möbius lattice whose control frames (X, Y, Z: arrows and a C handle each) you drag"""

    bl_idname = "ple.mobius_add"
    bl_label = "Add Möbius Lattice"
    bl_options = {"REGISTER", "UNDO"}

    preset: bpy.props.StringProperty(name="Preset", default="mobius_slab",
                                     description="a preset whose lattice is placed by Möbius transformations")

    def execute(self, context):
        try:
            rig = create(context, self.preset)
        except PleError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for obj in context.view_layer.objects.selected:
            obj.select_set(False)
        rig.select_set(True)
        context.view_layer.objects.active = rig
        return {"FINISHED"}


class PLE_OT_mobius_snippet(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Copy the frames as a program line, lat = with_control_frames(lat, {...}), to the text block
    "PLE snippet" and the clipboard (thesis §6.2.2: GUI edits become program text)"""

    bl_idname = "ple.mobius_snippet"
    bl_label = "Copy Frames as Code"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        return rig_of(context.active_object) is not None

    def execute(self, context):
        try:
            code = mobius.control_frames_code(frames_of(rig_of(context.active_object)))
        except PleError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        text = bpy.data.texts.get(SNIPPET_TEXT) or bpy.data.texts.new(SNIPPET_TEXT)
        text.from_string(code + "\n")
        context.window_manager.clipboard = code
        return {"FINISHED"}


class PLE_PT_mobius(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Möbius Frames"

    @classmethod
    def poll(cls, context):
        return rig_of(context.active_object) is not None

    def draw(self, context):
        rig = rig_of(context.active_object)
        col = self.layout.column()
        col.label(text=f"Preset: {rig['ple_mobius']}")
        col.label(text="Drag the frames X, Y, Z (arrows) and their C handles (spheres)")
        col.operator(PLE_OT_mobius_snippet.bl_idname, icon="COPYDOWN")
        if rig.get("ple_status"):
            col.label(text=rig["ple_status"], icon="ERROR")


def on_depsgraph_update(scene):
    """Redraw the Möbius rigs whose frames or handles moved (an ``updates`` hook of the rig's handler)."""
    for obj in scene.objects:
        if is_mobius_rig(obj):
            refresh(obj)


def meshed(obj):
    """(rig, fn -> (lattice, region)) for an object of a Möbius rig: Tessellate and Export mesh the
    lattice of its frames, whole (a ``meshed`` hook); None for other objects."""
    rig = rig_of(obj)
    if rig is None:
        return None

    def subject():
        lat = mobius.with_control_frames(base_lattice(rig), frames_of(rig))
        return lat, lat.region()

    return rig, subject


def route(preset: str) -> str | None:
    """Add › PLE Lattice of a Möbius preset makes a Möbius rig (a ``routes`` hook)."""
    return PLE_OT_mobius_add.bl_idname if preset in PRESETS else None


HOOKS = (("updates", on_depsgraph_update), ("routes", route), ("meshed", meshed))
CLASSES = (PLE_OT_mobius_add, PLE_OT_mobius_snippet, PLE_PT_mobius)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for name, fn in HOOKS:
        hooks.add(name, fn)


def unregister():
    for name, fn in HOOKS:
        hooks.remove(name, fn)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    SESSION.caches.pop("mobius", None)
