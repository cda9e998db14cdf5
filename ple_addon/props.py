"""Settings of PLE objects (a PropertyGroup on every Object, ``obj.ple``)."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    BoolVectorProperty,
    EnumProperty,
    IntProperty,
    IntVectorProperty,
    PointerProperty,
    StringProperty,
)

from .rig import events


def _rig_changed(self, context):
    events.on_settings_changed(self.id_data)


def _cumulative_changed(self, context):
    events.on_cumulative_changed(self.id_data)


def _counts_changed(self, context):
    events.on_counts_changed(self.id_data)


def _is_rig(self, obj):
    return obj.ple.role == "RIG" and obj != self.id_data


ROLES = [(r, r.title(), d) for r, d in (
    ("NONE", "not part of a PLE rig"), ("RIG", "the lattice object (root of a rig)"),
    ("FRAME", "a frame handle: placement G or the similarity U, V or W"),
    ("NODE", "a template node of the node-group N[0,0,0]"), ("CORNER", "a BeCOTS corner A, B, C or D"),
    ("CAGE", "isocurves of the steady 3-map"), ("REGION", "full drawing of the selected index box"),
    ("CLG", "preview of a CLG rig's solid over the selected index box"))]


class PLE_ObjectSettings(bpy.types.PropertyGroup):  # noqa: N801 - Blender naming
    role: EnumProperty(name="Role", items=ROLES, default="NONE")
    rig: PointerProperty(name="Rig", type=bpy.types.Object, description="The lattice object this part belongs to")
    frame: StringProperty(name="Frame", description="G, u, v or w")
    node_index: IntProperty(name="Node", min=0, description="Index of the template node")

    # ----- the lattice object ----------------------------------------------------------------
    text: PointerProperty(name="Program", type=bpy.types.Text,
                          description="The lattice program (a Python lattice(...) function) or an IR file")
    source_kind: EnumProperty(name="Source", items=[
        ("PROGRAM", "Program", "a Python lattice program (runs code: needs trusted scripts)"),
        ("IR", "IR", "a data-only ple-lattice/1 file (never runs code)")], default="PROGRAM")
    edits: StringProperty(name="GUI edits", default="[]",
                          description="GUI edits not yet written into the program (JSON)")
    counts: IntVectorProperty(name="Repetition counts", size=3, min=1, default=(1, 1, 1), update=_counts_changed,
                              description="Repetition counts of U, V and W (node-groups per steady row)")
    cumulative: BoolVectorProperty(name="Cumulative", size=3, default=(False, False, False),
                                   update=_cumulative_changed,
                                   description="Frames show the cumulative similarity (group 0 to the last "
                                               "group of the row) instead of the incremental one")
    region_min: IntVectorProperty(name="Region from", size=3, min=0, default=(0, 0, 0), update=_rig_changed,
                                  description="First node-group index (i, j, k) drawn in full")
    region_max: IntVectorProperty(name="Region to", size=3, min=1, default=(3, 3, 3), update=_rig_changed,
                                  description="End (exclusive) of the index box drawn in full")
    cage_interior: IntProperty(name="Cage lines", min=0, max=8, default=1, update=_rig_changed,
                               description="Interior isocurves of the steady 3-map per direction")
    show_template: BoolProperty(name="Template nodes", default=True, update=_rig_changed,
                                description="Show the template node-group as editable sphere empties")
    filter_kind: EnumProperty(name="Filter", update=_rig_changed, items=[
        ("NONE", "None", "draw every node of the region"),
        ("LIL", "LiL", "Lattice-in-Lattice: keep nodes whose ball interferes with a coarse lattice"),
        ("STENCIL", "Stencil", "index stencil: keep nodes by (i, j, k) modulo the stencil's shape")])
    coarse: PointerProperty(name="Coarse lattice", type=bpy.types.Object, poll=_is_rig, update=_rig_changed,
                            description="The coarse PLE lattice of the LiL filter")
    stencil_shape: IntVectorProperty(name="Stencil shape", size=3, min=1, max=16, default=(2, 2, 2),
                                     update=_rig_changed, description="Period of the index stencil along U, V, W")
    stencil_bits: StringProperty(name="Stencil", default="10010110", update=_rig_changed,
                                 description="0/1 per stencil cell in (i, j, k) order, k fastest")
    snippet_digits: IntProperty(name="Digits", min=1, max=15, default=6,
                                description="Decimals in copied snippets (applying always writes 12)")
    uid: StringProperty(name="Id", options={"HIDDEN"},
                        description="Stable id of the lattice object (trust and state survive renaming)")
    filepath: StringProperty(name="Program file", subtype="FILE_PATH",
                             description="The file on disk the program text was loaded from (Reload / Save)")
    folder: StringProperty(name="Folder", subtype="DIR_PATH",
                           description="Where a body mesh the IR names is found (its file's folder, the presets')")
    status: StringProperty(name="Status", description="Last problem met while evaluating the lattice")
    message: StringProperty(name="Message", description="Progress or result of the last job (tessellate, export, LiL)")


def register():
    bpy.utils.register_class(PLE_ObjectSettings)
    bpy.types.Object.ple = PointerProperty(type=PLE_ObjectSettings)


def unregister():
    del bpy.types.Object.ple
    bpy.utils.unregister_class(PLE_ObjectSettings)
