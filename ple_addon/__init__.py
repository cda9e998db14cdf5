"""PLE — Programmed Lattice Editor for Blender (thesis §6.2, SPEC §7).

A thin skin over the core package ``ple``: frames (empties) that define the placement G and
the similarities U, V, W, a cage of isocurves, a fully drawn index region, template editing,
code snippets of GUI edits, filters, tessellation and export. Live editing runs in a
``depsgraph_update_post`` handler (msgbus and timers do not fire in background mode).
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import operators, props, rig, ui


@persistent
def on_depsgraph_update(scene, depsgraph):
    for r in rig.rigs_in_updates(depsgraph):
        rig.refresh(r)


@persistent
def on_reset(*_args):
    """After undo, redo or loading a file, positions are the saved state, not user moves."""
    rig.clear_state()
    for r in rig.all_rigs():
        rig.refresh(r, force=True)


HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("undo_post", on_reset), ("redo_post", on_reset),
            ("load_post", on_reset))


def menu_add(self, context):
    self.layout.operator("ple.lattice_add", text="PLE Lattice", icon="LIGHTPROBE_VOLUME")


def register():
    props.register()
    for cls in operators.CLASSES + ui.CLASSES:
        bpy.utils.register_class(cls)
    for name, fn in HANDLERS:
        getattr(bpy.app.handlers, name).append(fn)
    bpy.types.VIEW3D_MT_add.append(menu_add)


def unregister():
    bpy.types.VIEW3D_MT_add.remove(menu_add)
    for name, fn in HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn in lst:
            lst.remove(fn)
    for cls in reversed(operators.CLASSES + ui.CLASSES):
        bpy.utils.unregister_class(cls)
    props.unregister()
    rig.clear_state()
