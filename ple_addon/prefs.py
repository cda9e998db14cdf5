"""Add-on preferences: the work budget, the program and job time limits (Edit › Preferences ›
Add-ons › PLE). Outside Blender's preferences (a source checkout) the defaults apply."""

from __future__ import annotations

import bpy
from bpy.props import FloatProperty, IntProperty

DEFAULTS = {"memory_gb": 2.0, "max_triangles": 10_000_000, "program_seconds": 10.0, "job_seconds": 600.0}


class PLE_AddonPreferences(bpy.types.AddonPreferences):  # noqa: N801 - Blender naming
    bl_idname = __package__

    memory_gb: FloatProperty(name="Memory limit (GB)", min=0.001, default=DEFAULTS["memory_gb"],
                             description="Drawing a region or tessellating is refused when its estimate "
                                         "(from counts and template, before any evaluation) exceeds this")
    max_triangles: IntProperty(name="Triangle limit", min=1000, default=DEFAULTS["max_triangles"],
                               description="Tessellation and export are refused beyond this estimated "
                                           "number of triangles")
    program_seconds: FloatProperty(name="Program time limit (s)", min=0.0, default=DEFAULTS["program_seconds"],
                                   description="A lattice program (or a filtered redraw) running longer is "
                                               "stopped with a report (0: no limit)")
    job_seconds: FloatProperty(name="Job time limit (s)", min=0.0, default=DEFAULTS["job_seconds"],
                               description="Tessellation, export and filter jobs running longer are stopped "
                                           "with a report (0: no limit; Esc stops them at any time)")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "memory_gb")
        col.prop(self, "max_triangles")
        col.prop(self, "program_seconds")
        col.prop(self, "job_seconds")


def settings():
    addon = bpy.context.preferences.addons.get(__package__)
    return getattr(addon, "preferences", None) if addon is not None else None


def get(name: str):
    prefs = settings()
    return getattr(prefs, name) if prefs is not None else DEFAULTS[name]


def max_bytes() -> float:
    return float(get("memory_gb")) * 2**30


CLASSES = (PLE_AddonPreferences,)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
