"""PLE — Programmed Lattice Editor for Blender (thesis §6.2, SPEC §7).

A thin skin over the core package ``ple``: frames (empties) that define the placement G and
the similarities U, V, W, a cage of isocurves, a fully drawn index region, template editing,
code snippets of GUI edits, filters, tessellation and export. Live editing runs in a
``depsgraph_update_post`` handler (msgbus and timers do not fire in background mode).
"""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import body_panel, check_panel, clg_rig, mobius_frames, operators, prefs, props, rig, ui


@persistent
def on_depsgraph_update(scene, depsgraph):
    """The add-on's one depsgraph handler: the updates are read before anything is deleted."""
    bodies = body_panel.rigs_in_updates(depsgraph)  # rigs whose body or gradient empty changed
    rig.check_removed(scene)  # parts of a rig whose lattice object was deleted go with it
    done = set()
    for r in rig.rigs_in_updates(depsgraph):
        rig.refresh(r)
        done.add(r.name)
    for name in bodies:
        r = bpy.data.objects.get(name)
        if r is not None and name not in done:
            rig.refresh(r)
    mobius_frames.on_depsgraph_update(scene)  # Möbius rigs whose control frames moved


@persistent
def on_load(*_args):
    """Trust belongs to the file it was given in: opening another .blend (even a copy holding the
    same rig ids) trusts nothing; reopening the same file keeps it (Blender's own trust applies)."""
    rig.forget_trust_of_other_files(bpy.data.filepath)
    on_reset()


@persistent
def on_save(*_args):
    rig.trusted_file(bpy.data.filepath)


@persistent
def on_reset(*_args):
    """After undo, redo or loading a file, positions are the saved state, not user moves
    (they are kept as the baseline, so moves made before Run Program still count)."""
    rig.clear_state()
    for r in rig.all_rigs():
        rig.claim(r)
        rig.baseline(r)
    for r in rig.all_rigs():
        rig.refresh(r, force=True)


HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("undo_post", on_reset), ("redo_post", on_reset),
            ("load_post", on_load), ("save_post", on_save))


def menu_add(self, context):
    self.layout.menu(ui.PLE_MT_add.bl_idname, text="PLE Lattice", icon="LIGHTPROBE_VOLUME")


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


def register():
    props.register()
    for cls in prefs.CLASSES + operators.CLASSES + ui.CLASSES:
        bpy.utils.register_class(cls)
    check_panel.register()
    for name, fn in HANDLERS:
        getattr(bpy.app.handlers, name).append(fn)
    body_panel.register()
    bpy.types.VIEW3D_MT_add.append(menu_add)
    clg_rig.register()
    register_keymap()
    ui.load_previews()
    mobius_frames.register()


def unregister():
    mobius_frames.unregister()
    ui.free_previews()
    unregister_keymap()
    clg_rig.unregister()
    bpy.types.VIEW3D_MT_add.remove(menu_add)
    body_panel.unregister()
    for name, fn in HANDLERS:
        lst = getattr(bpy.app.handlers, name)
        if fn in lst:
            lst.remove(fn)
    check_panel.unregister()
    for cls in reversed(prefs.CLASSES + operators.CLASSES + ui.CLASSES):
        bpy.utils.unregister_class(cls)
    props.unregister()
    rig.clear_state()
