"""Operators that make meshes and files of the drawn region: tessellate into an object, export a
file (both jobs: progress, Esc cancels), bake the drawing into a plain mesh."""

from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
from bpy.props import (
    EnumProperty,
    StringProperty,
)

from .. import draw
from ..corelink import PleError, needs
from ..rig import hooks, model, sync
from .base import BEYOND, EXPORT_STYLES, STYLES, SteppedOperator, budget, core_style, output_path


class MeshOperator(SteppedOperator):
    """Tessellate and Export: of a steady rig's drawn region, or of a rig a feature meshes (the
    ``meshed`` hook: a Möbius rig, whole)."""

    def get_rig(self, context):
        other = hooks.first("meshed", bpy.data.objects.get(self.rig) if self.rig else context.active_object)
        return other[0] if other is not None else super().get_rig(context)

    @classmethod
    def poll(cls, context):
        return hooks.first("meshed", getattr(context, "active_object", None)) is not None or super().poll(context)

    def mesh_object(self, rig, lat, region, style: str, name: str, collections):
        """Steps: the region's mesh in ``style`` from the core's one pipeline, welded in a child
        job and mapped from its files, as a new object ``name`` in ``collections`` placed as the
        rig; the rig's status names unclean hubs the mesh united. Returns the object."""
        request = needs("app.pipeline").MeshRequest(lat, region, style)
        with tempfile.TemporaryDirectory(prefix="ple-mesh-", ignore_cleanup_errors=True) as tmp:
            verts, faces, report = yield from self.mesh_job(request, Path(tmp))  # mapped, welded in the child
            if not len(faces):
                raise PleError(f"nothing to mesh: region {region} keeps no ball (move Region from/to)")
            yield 0.9
            me = draw.mesh_from_arrays(name, verts, faces)
            del verts, faces  # the maps closed before their folder goes
        obj = bpy.data.objects.new(me.name, me)
        for coll in collections:
            coll.objects.link(obj)
        obj.matrix_world = rig.matrix_world
        say_unclean(rig, report)
        return obj

    def subject(self, rig):
        """(lattice, region) to mesh: what is drawn (the panel's filter too) is what is meshed."""
        other = hooks.first("meshed", rig)
        if other is not None:
            return other[1]()
        lat = model.shown_lattice(rig)
        region = model.region_of(rig, lat)
        if region is None:
            raise PleError("the region is empty: set Region from/to inside the repetition counts")
        return lat, region


class PLE_OT_tessellate(MeshOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Tessellate the drawn region into a new mesh object (CHoCC, CNT or refined, CHoCC paper)"""

    bl_idname = "ple.tessellate"
    bl_label = "Tessellate Region"

    style: EnumProperty(name="Style", items=STYLES, default="CHOCC")
    beyond_limit: BEYOND

    def steps(self, context, rig):
        self._rig = rig
        lat, region = self.subject(rig)
        budget(lat, region, self.style, f"{self.style.lower()} tessellation of {region}",
               beyond=self.beyond_limit)
        yield 0.0
        # the core's one mesh pipeline (``ple.app.pipeline``): checked for unclean hubs, their
        # local unions included, on the region's float32 grid: the triangles `ple mesh` writes
        obj = yield from self.mesh_object(rig, lat, region, core_style(self.style),
                                          f"{rig.name}.{self.style.lower()}", rig.users_collection)
        self.result = f"{obj.name}: {len(obj.data.polygons)} triangles"
        yield 1.0


class PLE_OT_export(MeshOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Export the drawn region as a mesh file (STL, 3MF, PLY, OBJ, GLB)"""

    bl_idname = "ple.export"
    bl_label = "Export Region"

    filepath: StringProperty(name="File", subtype="FILE_PATH")
    filter_glob: StringProperty(default="*.stl;*.3mf;*.ply;*.obj;*.glb", options={"HIDDEN"})
    style: EnumProperty(name="Style", items=EXPORT_STYLES, default="REFINED")
    beyond_limit: BEYOND

    def invoke(self, context, event):
        if not self.filepath and context.window is not None and not bpy.app.background:
            self.filepath = "lattice.stl"
            context.window_manager.fileselect_add(self)
            return {"RUNNING_MODAL"}
        return super().invoke(context, event)

    def steps(self, context, rig):
        self._rig = rig
        path = output_path(self.filepath)
        lat, region = self.subject(rig)
        streamed = path.suffix.lower() == ".stl"
        budget(lat, region, self.style, f"export of {region}", streamed=streamed, beyond=self.beyond_limit)
        yield 0.0
        # the file `ple mesh` writes for the same request (``ple.app.pipeline.write_mesh``): the
        # unclean check and its local unions, the float32 grid, the atomic write
        request = needs("app.pipeline").MeshRequest(lat, region, core_style(self.style))
        count, report = yield from self.file_job(request, path)
        self.result = f"{count} triangles written to {path}"
        say_unclean(rig, report)
        yield 1.0


def say_unclean(rig, report) -> None:
    """The rig's status: the unclean hubs the mesh united locally, until the next edit (empty when
    clean)."""
    if report and model.is_rig(rig):
        sync.note(rig, report)
    else:
        rig.ple.status = report or ""


class PLE_OT_bake(MeshOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Freeze the drawn region into a plain mesh object of balls and beams: the preview style of the
    core's one mesh pipeline, the triangles `ple mesh --style balls-beams` writes (a job: Esc cancels)"""

    bl_idname = "ple.bake"
    bl_label = "Bake Region"

    beyond_limit: BEYOND

    def steps(self, context, rig):
        self._rig = rig
        lat, region = self.subject(rig)
        budget(lat, region, "BALLS_BEAMS", f"baking region {region}", beyond=self.beyond_limit)
        yield 0.0
        obj = yield from self.mesh_object(rig, lat, region, "balls-beams", f"{rig.name}.baked",
                                          [context.scene.collection])
        draw.set_material(obj, draw.REGION_MATERIAL)
        self.result = f"{obj.name}: {len(obj.data.polygons)} faces"
        yield 1.0


CLASSES = (PLE_OT_tessellate, PLE_OT_export, PLE_OT_bake)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
