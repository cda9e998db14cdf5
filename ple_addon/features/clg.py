"""The CLG rig (thesis §5, §10): a lattice rig whose text holds a CLG (a ``clg()`` program or a
``ple-clg/1`` file); its frames, corners and template nodes edit the CLG's pattern as a lattice
rig's (through the rig's hooks), the chunks, solid and materials stay as the text gives them. Over
the drawn region it previews the solid (or one chunk union): the core's manifold3d mesh, its voxels
or one printer layer; voxelize, slice and export operators. Every number comes from the core.
"""

from __future__ import annotations

import json
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, IntVectorProperty, StringProperty

from .. import draw, jobs
from ..corelink import PleError, core, ir, needs
from ..ops.base import RigOperator, RigPanel, SourceAdd, draw_source_menu, output_path, select_only
from ..rig import hooks, model, sync
from ..session import SESSION, notify

clg_sources = core("program.clg_sources")
clg_ir = core("clg.ir")
clg_grid = core("clg.grid")
clg_query = core("clg.query")
files = core("io.files")

PREVIEW_MATERIAL = ("PLE CLG", (0.85, 0.75, 0.2, 1.0))
PREVIEWS = [("NONE", "None", "no preview (the region's balls and beams only)"),
            ("MESH", "Mesh", "the solid meshed by the core (manifold3d booleans)"),
            ("VOXELS", "Voxels", "the solid's voxels over the region's box"),
            ("SLICE", "Slice", "one printer layer of voxels at the chosen height")]
LOADED = 8  # CLG texts (with their inputs) kept loaded


# ----- settings ---------------------------------------------------------------------------------------
def _preview_changed(self, context):
    rig = self.id_data
    if model.is_rig(rig) and self.active and not SESSION.busy:
        show_preview(rig)


class PLE_CLGSettings(bpy.types.PropertyGroup):  # noqa: N801 - Blender naming
    active: BoolProperty(name="CLG rig", default=False, options={"HIDDEN"},
                         description="The rig's text is a CLG; its lattice is the CLG's pattern")
    preview: EnumProperty(name="Preview", items=PREVIEWS, default="MESH", update=_preview_changed)
    live: BoolProperty(name="Live", default=True, update=_preview_changed,
                       description="Recompute the preview after every edit (off: only with Preview)")
    chunk: StringProperty(name="Show chunk", default="", update=_preview_changed,
                          description="Preview one chunk union instead of the solid (empty: the solid)")
    segments: IntProperty(name="Segments", min=8, max=128, default=16, update=_preview_changed,
                          description="Circle segments of the meshed balls and beams")
    voxels: IntProperty(name="Voxels", min=4, max=160, default=48, update=_preview_changed,
                        description="Voxels along the longest side of the region's box")
    slice_height: FloatProperty(name="Height", min=0.0, max=1.0, default=0.5, subtype="FACTOR",
                                update=_preview_changed, description="Layer height within the region's box")
    status: StringProperty(name="Status", description="Last problem met while computing the preview")


# ----- the CLG of a rig -------------------------------------------------------------------------------
def load(kind: str, source: str, params: dict, name: str):
    """(program inputs or None, CLG) of a rig's text: a ``ple-clg/1`` file or a program defining ``clg()``
    (the caller checked trust); kept for the latest few texts and inputs."""
    key = (kind, source, model.params_key(params))
    loaded = SESSION.cache("clg")
    hit = loaded.get(key)
    if hit is None:
        if kind == "IR":
            hit = (None, clg_ir.clg_from_dict(model.read_json(source, name)))
        else:
            def build():  # run contained: time and memory limits, like lattice programs
                prog = clg_sources.compile_clg_program(source, name)
                return prog.parameters(), prog.run(**params)

            hit = jobs.call(build, name, "the CLG program")
        loaded[key] = hit
        while len(loaded) > LOADED:
            loaded.pop(next(iter(loaded)))
    return hit


def base_clg(rig):
    """The CLG the rig's text gives (before GUI edits of its pattern)."""
    text = rig.ple.text
    if text is None:
        raise PleError(f"{rig.name}: the CLG text block is missing")
    if not model.trusted(rig):
        raise PleError(f"{text.name}: not run because Blender does not trust scripts (press Run Program)")
    return load(rig.ple.source_kind, text.as_string(), model.params_of(rig), text.name)[1]


def pattern_of(rig, source: str, params: dict, name: str):
    """(program inputs or None, the CLG's pattern) of a CLG rig's text (a ``loaders`` hook of the rig)."""
    if not rig.ple_clg.active:
        return None
    inputs, clg = load(rig.ple.source_kind, source, params, name)
    return inputs, clg.pattern


def clg_of(rig, lat=None):
    """The rig's current CLG: its text's chunks, solid and materials on the edited pattern ``lat``
    (default: the rig's lattice), the solid or the chunk union named in the panel."""
    clg = base_clg(rig)
    lat = model.lattice_of(rig) if lat is None else lat
    chunk = rig.ple_clg.chunk.strip()
    return clg.with_pattern(lat).showing(chunk or None)


def applied_text(rig) -> str | None:
    """The CLG text with the GUI edits of its pattern written in (Apply to Program, an ``appliers``
    hook; None for other rigs): a ``ple-clg/1`` file gets the edited pattern as its ``pattern``
    object; a clg() program is refused (its lattice is built inside clg(): copy the snippet)."""
    if not rig.ple_clg.active:
        return None
    if rig.ple.source_kind != "IR":
        raise PleError("Apply to Program rewrites ple-clg/1 files only; for a clg() program use Copy Snippet "
                       "and paste the lines where clg() builds its pattern")
    data = json.loads(rig.ple.text.as_string())
    data["pattern"] = ir.lattice_to_ir(model.lattice_of(rig), resolved=False)
    return json.dumps(data, indent=1) + "\n"


def clg_rig_of(context, name: str = ""):
    obj = bpy.data.objects.get(name) if name else context.active_object
    rig = model.rig_of(obj)
    if rig is None or not rig.ple_clg.active:
        raise PleError("select a PLE CLG object (or one of its frames)")
    return rig


# ----- the preview --------------------------------------------------------------------------------
def grid_shape(lo, hi, n: int) -> tuple[int, int, int]:
    """Voxel counts with n along the longest side of [lo, hi], near-cubic voxels."""
    ext = np.maximum(np.asarray(hi, float) - np.asarray(lo, float), 1e-12)
    return tuple(int(max(1, round(n * e / ext.max()))) for e in ext)


def preview_arrays(rig, lat=None):
    """(vertices (n, 3), faces (f, k)) of the rig's preview, in the rig's coordinates."""
    s = rig.ple_clg
    clg = clg_of(rig, lat)
    region = model.region_of(rig, clg.pattern)
    if region is None or s.preview == "NONE":
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    if s.preview == "MESH":
        mesh = needs("meshing.clg").mesh_clg(clg, s.segments, region)
        return np.asarray(mesh.vertices), np.asarray(mesh.faces)
    comp = clg_query.compiled(clg, region)
    lo, hi = comp.lo.copy(), comp.hi.copy()
    shape = grid_shape(lo, hi, s.voxels)
    if s.preview == "SLICE":  # one layer, a voxel thick
        step = (hi[2] - lo[2]) / shape[2]
        z = lo[2] + s.slice_height * (hi[2] - lo[2])
        lo[2], hi[2] = z - step / 2, z + step / 2
        shape = (shape[0], shape[1], 1)
    vox = clg_grid.voxelize_clg(comp, lo, hi, shape)
    return clg_grid.voxel_surface(vox, lo, hi)


def show_preview(rig, lat=None) -> str | None:
    """Recompute the preview; a problem (bad chunk name, a missing package, …) leaves the last good
    preview and becomes the CLG status (returned)."""
    try:
        verts, faces = preview_arrays(rig, lat)
    except PleError as exc:
        rig.ple_clg.status = str(exc)
        return str(exc)
    obj = sync.mesh_part(rig, "CLG", PREVIEW_MATERIAL)
    draw.mesh_from_arrays(obj.name, verts, faces, obj.data)
    obj.hide_viewport = obj.hide_render = rig.ple_clg.preview == "NONE"
    if rig.ple_clg.status:
        rig.ple_clg.status = ""
    return None


def on_drawn(rig, lat) -> None:
    """After the rig drew its region (an ``after_draw`` hook): a live preview follows the edit."""
    if rig.ple_clg.active and rig.ple_clg.live:
        err = show_preview(rig, lat)
        if err:
            notify(rig, err)


# ----- operators --------------------------------------------------------------------------------------
def _preset_items(self, context):
    return [(n, n, f"CLG preset {n}") for n in clg_sources.clg_preset_names()]


class PLE_OT_clg_add(SourceAdd, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a PLE CLG rig from a CLG preset, a program defining clg() (.py), a ple-clg/1 file (.json)
    or a text block"""

    bl_idname = "ple.clg_add"
    bl_label = "Add PLE CLG"
    bl_options = {"REGISTER", "UNDO"}

    source: EnumProperty(name="From", items=[
        ("PRESET", "Preset", "a CLG shipped with PLE"),
        ("FILE", "File", "a CLG program .py or a data-only ple-clg/1 .json"),
        ("TEXT", "Text Block", "a text block of this file holding a CLG program or ple-clg/1 data")],
        default="PRESET")
    preset: EnumProperty(name="Preset", items=_preset_items)

    what = ".py CLG program or .json ple-clg/1 file"

    def preset_file(self) -> Path:
        return clg_sources.resolve_clg(self.preset)

    def execute(self, context):
        try:
            text, kind, default_name, linked, folder = self.source_text()
            rig = sync.create(context, self.name or default_name, text, kind, tuple(self.region), clg=True,
                              folder=folder)
        except PleError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        rig.ple.filepath = linked
        select_only(context, rig)
        if rig.ple_clg.status:
            self.report({"WARNING"}, rig.ple_clg.status)
        return {"FINISHED"}


class CLGOperator(RigOperator):
    """A rig operator that needs a CLG rig."""

    def get_rig(self, context):
        return clg_rig_of(context, self.rig)


WHOLE = BoolProperty(name="Whole CLG", default=False,
                     description="Every chunk copy of the pattern's counts (default: the selected region's)")


def target(rig, whole: bool):
    """(compiled CLG, its clg) of the region (or the whole CLG)."""
    clg = clg_of(rig)
    region = None if whole else model.region_of(rig, clg.pattern)
    if region is None and not whole:
        raise PleError("the region is empty: set Region from/to inside the repetition counts")
    return clg_query.compiled(clg, region), clg, region


class PLE_OT_clg_preview(CLGOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Recompute the CLG preview of the selected region now"""

    bl_idname = "ple.clg_preview"
    bl_label = "Preview"

    def run(self, context, rig):
        err = show_preview(rig)
        if err:
            raise PleError(err)
        return {"FINISHED"}


class PLE_OT_clg_voxelize(CLGOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Voxelize the CLG solid into a bool .npy array (NX, NY, NZ) of the voxel centres (thesis §5.6)"""

    bl_idname = "ple.clg_voxelize"
    bl_label = "Voxelize"

    filepath: StringProperty(name="File", subtype="FILE_PATH", description="output .npy")
    grid: IntVectorProperty(name="Grid", size=3, min=1, max=1024, default=(64, 64, 64))
    whole: WHOLE

    def run(self, context, rig):
        path = output_path(self.filepath, (".npy",))
        comp, _clg, _region = target(rig, self.whole)
        vox = clg_grid.voxelize_clg(comp, comp.lo, comp.hi, tuple(self.grid))
        with files.atomic_path(path) as tmp:
            with open(tmp, "wb") as fh:
                np.save(fh, vox)
        self.report({"INFO"}, f"{int(vox.sum())} of {vox.size} voxels inside, written to {path}")
        return {"FINISHED"}


class PLE_OT_clg_slice(CLGOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Printer slices of the CLG solid: one 1-bit PNG per layer and a manifest.json"""

    bl_idname = "ple.clg_slice"
    bl_label = "Slice"

    directory: StringProperty(name="Folder", subtype="DIR_PATH")
    layer: FloatProperty(name="Layer", min=1e-6, default=0.05, description="layer height")
    pixel: FloatProperty(name="Pixel", min=1e-6, default=0.05, description="pixel size")
    whole: WHOLE

    def run(self, context, rig):
        if not self.directory:
            raise PleError("choose an output folder")
        comp, _clg, _region = target(rig, self.whole)
        man = core("io.slices").write_pmc_slices(bpy.path.abspath(self.directory), comp.pmc, comp.lo, comp.hi,
                                                 self.layer, self.pixel)
        self.report({"INFO"}, f"{man['layers']} layers of {man['image_size'][0]}x{man['image_size'][1]} pixels")
        return {"FINISHED"}


class PLE_OT_clg_export(CLGOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Export the CLG solid as a watertight mesh file (STL, 3MF, PLY, OBJ, GLB)"""

    bl_idname = "ple.clg_export"
    bl_label = "Export CLG"

    filepath: StringProperty(name="File", subtype="FILE_PATH")
    segments: IntProperty(name="Segments", min=8, max=512, default=32)
    whole: WHOLE

    def run(self, context, rig):
        path = output_path(self.filepath)
        _comp, clg, region = target(rig, self.whole)
        mesh = needs("meshing.clg").mesh_clg(clg, self.segments, region)
        needs("io.export").export_mesh(mesh, path)
        self.report({"INFO"}, f"{len(mesh.faces)} triangles written to {path}")
        return {"FINISHED"}


# ----- the panel and the Add menu ---------------------------------------------------------------
class PLE_PT_clg(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "CLG"

    @classmethod
    def poll(cls, context):
        rig = model.rig_of(context.active_object)
        return rig is not None and rig.ple_clg.active

    def draw(self, context):
        rig = model.rig_of(context.active_object)
        s = rig.ple_clg
        layout = self.layout
        try:
            clg = base_clg(rig)
        except PleError as exc:
            layout.label(text=str(exc), icon="ERROR")
            clg = None
        if clg is not None:
            box = layout.column(align=True)
            for name, expr in clg.chunks.items():
                used = "" if name in clg.used_chunks() else "  (not in the solid)"
                box.label(text=f"chunk {name}: {len(core('clg.model').leaves(expr))} primitives{used}")
            box.label(text=f"solid: {json.dumps(clg_ir.expr_to_dict(clg.solid))}")
            box.label(text=f"materials: {', '.join(sorted(clg.materials)) or '-'}, depth {clg.depth}")
        layout.prop(s, "chunk")
        row = layout.row(align=True)
        row.prop(s, "preview", expand=True)
        if s.preview == "MESH":
            layout.prop(s, "segments")
        elif s.preview in ("VOXELS", "SLICE"):
            layout.prop(s, "voxels")
            if s.preview == "SLICE":
                layout.prop(s, "slice_height")
        row = layout.row(align=True)
        row.prop(s, "live")
        row.operator("ple.clg_preview", icon="FILE_REFRESH")
        row = layout.row(align=True)
        row.operator("ple.clg_voxelize", icon="MESH_GRID")
        row.operator("ple.clg_slice", icon="IMAGE_DATA")
        row.operator("ple.clg_export", icon="EXPORT")
        for msg in (s.status, rig.ple.status):
            if msg:
                layout.label(text=msg, icon="ERROR")


class PLE_MT_clg_add(bpy.types.Menu):  # noqa: N801 - Blender naming
    """Add › PLE CLG: a CLG preset or a CLG program / ple-clg/1 file"""

    bl_idname = "PLE_MT_clg_add"
    bl_label = "PLE CLG"

    def draw(self, context):
        draw_source_menu(self.layout, "ple.clg_add", clg_sources.clg_preset_names(), "MOD_BOOLEAN")


def menu_add(self, context):
    self.layout.menu(PLE_MT_clg_add.bl_idname, text="PLE CLG", icon="MOD_BOOLEAN")


HOOKS = (("loaders", pattern_of), ("after_draw", on_drawn), ("appliers", applied_text))
CLASSES = (PLE_CLGSettings, PLE_OT_clg_add, PLE_OT_clg_preview, PLE_OT_clg_voxelize, PLE_OT_clg_slice,
           PLE_OT_clg_export, PLE_PT_clg, PLE_MT_clg_add)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.ple_clg = bpy.props.PointerProperty(type=PLE_CLGSettings)
    bpy.types.VIEW3D_MT_add.append(menu_add)
    for name, fn in HOOKS:
        hooks.add(name, fn)


def unregister() -> None:
    for name, fn in HOOKS:
        hooks.remove(name, fn)
    bpy.types.VIEW3D_MT_add.remove(menu_add)
    del bpy.types.Object.ple_clg
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    SESSION.caches.pop("clg", None)
