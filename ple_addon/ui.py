"""The "PLE" sidebar tab of the 3D viewport: Program, Frames, Region, Template, Filters,
Tessellate & Export (thesis §6.2.2)."""

from __future__ import annotations

import bpy

from .corelink import PleError, presets, snippets
from .ops.base import RigPanel, draw_source_menu
from .rig import model
from .session import SESSION

_previews = {}


def load_previews() -> None:
    """Preset thumbnails (shipped in presets/thumbnails) for the Add menu."""
    import bpy.utils.previews

    coll = bpy.utils.previews.new()
    thumbs = presets.preset_dir() / "thumbnails"
    for name in presets.preset_names():
        png = thumbs / f"{name}.png"
        if png.is_file():
            coll.load(name, str(png), "IMAGE")
    _previews["presets"] = coll


def free_previews() -> None:
    import bpy.utils.previews

    coll = _previews.pop("presets", None)
    if coll is not None:
        bpy.utils.previews.remove(coll)


def preset_icon(name: str) -> int:
    coll = _previews.get("presets")
    return coll[name].icon_id if coll is not None and name in coll else 0


class PLE_MT_add(bpy.types.Menu):  # noqa: N801 - Blender naming
    """Add › PLE Lattice: a preset (with its thumbnail) or a program / IR file"""

    bl_idname = "PLE_MT_add"
    bl_label = "PLE Lattice"

    def draw(self, context):
        draw_source_menu(self.layout, "ple.lattice_add", presets.preset_names(), "LIGHTPROBE_VOLUME", preset_icon)


class PLE_PT_program(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Program"

    @classmethod
    def poll(cls, context):
        return True

    def draw(self, context):
        layout = self.layout
        layout.operator("ple.lattice_add", icon="ADD")
        rig = self.rig(context)
        if rig is None:
            return
        p = rig.ple
        layout.prop(p, "text")
        for key in [k for k in rig.keys() if k.startswith(model.PARAM_PREFIX)]:
            layout.prop(rig, f'["{key}"]', text=key[len(model.PARAM_PREFIX):], slider=True)
        row = layout.row(align=True)
        row.operator("ple.program_run", icon="PLAY")
        row.operator("ple.program_apply", icon="FILE_REFRESH")
        if p.filepath:
            row = layout.row(align=True)
            row.label(text=p.filepath, icon="FILE")
            row.operator("ple.program_reload", text="", icon="FILE_REFRESH")
            row.operator("ple.program_save", text="", icon="FILE_TICK")
        row = layout.row(align=True)
        row.operator("ple.snippet_copy", icon="COPYDOWN")
        row.prop(p, "snippet_digits")
        try:
            n = len(snippets.coalesce(model.edits_of(rig)))
        except PleError:
            n = 0
        row = layout.row()
        row.label(text=f"{n} GUI edit(s) not in the program")
        row.operator("ple.edits_clear", text="", icon="X")
        row = layout.row(align=True)
        row.operator("ple.duplicate", icon="DUPLICATE")
        row.operator("ple.bake", icon="MESH_DATA")
        row.operator("ple.remove", icon="TRASH")
        if p.status:
            layout.label(text=p.status, icon="ERROR")
        if p.message:
            layout.label(text=p.message, icon="INFO")


class PLE_PT_frames(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Frames"

    def draw(self, context):
        rig = self.rig(context)
        layout = self.layout
        layout.label(text="Drag, rotate or scale a frame: G places the lattice,")
        layout.label(text="U, V, W are the similarities of the steady rows.")
        parts = model.parts(rig)
        col = layout.column(align=True)
        for n, axis in enumerate("uvw"):
            row = col.row(align=True)
            frame = parts.get(axis)
            row.label(text=f"{axis.upper()}: {frame.name if frame else '-'}")
            row.prop(rig.ple, "cumulative", index=n, text="Cumulative", toggle=True)
        layout.prop(rig.ple, "counts")


class PLE_PT_region(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Region"

    def draw(self, context):
        p = self.rig(context).ple
        layout = self.layout
        layout.prop(p, "region_min")
        layout.prop(p, "region_max")
        layout.prop(p, "cage_interior")


class PLE_PT_template(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Template"

    def draw(self, context):
        rig = self.rig(context)
        layout = self.layout
        layout.prop(rig.ple, "show_template")
        row = layout.row(align=True)
        row.operator("ple.node_add", icon="ADD")
        row.operator("ple.node_remove", icon="REMOVE")
        layout.operator("ple.beam_add", icon="ADD")
        st = SESSION.states.get(rig.ple.uid)
        if st is not None and st.lattice is not None:
            for b, beam in enumerate(st.lattice.beams):
                row = layout.row()
                row.label(text=f"{b}: node {beam.n1} -> node {beam.n2} at ({beam.di}, {beam.dj}, {beam.dk})")
                row.operator("ple.beam_remove", text="", icon="X").index = b


class PLE_PT_filters(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Filters"

    def draw(self, context):
        p = self.rig(context).ple
        layout = self.layout
        layout.prop(p, "filter_kind")
        if p.filter_kind == "LIL":
            layout.prop(p, "coarse")
        elif p.filter_kind == "STENCIL":
            layout.prop(p, "stencil_shape")
            layout.prop(p, "stencil_bits")
        row = layout.row(align=True)
        row.operator("ple.lil_filter")
        row.operator("ple.stencil_filter")


class PLE_PT_output(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Tessellate & Export"

    def draw(self, context):
        layout = self.layout
        row = layout.row(align=True)
        for style in ("CHOCC", "CNT", "REFINED"):
            row.operator("ple.tessellate", text=style.title() if style != "CHOCC" else "CHoCC").style = style
        layout.operator("ple.export", icon="EXPORT")


CLASSES = (PLE_MT_add, PLE_PT_program, PLE_PT_frames, PLE_PT_region, PLE_PT_template, PLE_PT_filters, PLE_PT_output)


# (operator, key, modifiers): in the 3D viewport, Object Mode
KEYMAP = (("ple.program_run", "R", {"ctrl": True, "alt": True}),
          ("ple.program_apply", "A", {"ctrl": True, "alt": True}),
          ("ple.snippet_copy", "C", {"ctrl": True, "alt": True}),
          ("ple.duplicate", "D", {"ctrl": True, "alt": True}),
          ("ple.remove", "X", {"ctrl": True, "alt": True}))
_keymap_items: list = []


def register_keymap():
    kc = bpy.context.window_manager.keyconfigs.addon
    if kc is None:  # background mode has no add-on key configuration
        return
    km = kc.keymaps.new(name="Object Mode", space_type="EMPTY")
    for idname, key, mods in KEYMAP:
        _keymap_items.append((km, km.keymap_items.new(idname, key, "PRESS", **mods)))


def unregister_keymap():
    for km, kmi in _keymap_items:
        km.keymap_items.remove(kmi)
    _keymap_items.clear()


def menu_add(self, context):
    self.layout.menu(PLE_MT_add.bl_idname, text="PLE Lattice", icon="LIGHTPROBE_VOLUME")


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.VIEW3D_MT_add.append(menu_add)
    load_previews()
    register_keymap()


def unregister() -> None:
    unregister_keymap()
    free_previews()
    bpy.types.VIEW3D_MT_add.remove(menu_add)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
