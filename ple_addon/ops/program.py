"""Operators of the program: add a lattice, run, apply, copy a snippet, discard edits, reload and
save the program file; and the rig as a whole: remove, duplicate; the report of live editing."""

from __future__ import annotations

import json
from pathlib import Path

import bpy
from bpy.props import (
    EnumProperty,
    StringProperty,
)

from .. import jobs
from ..corelink import PleError, core, ir, presets, snippets
from ..rig import hooks, model, sync
from .base import SNIPPET_TEXT, RigOperator, SourceAdd, select_only


def _preset_items(self, context):
    return [(n, n, presets.preset_description(n)) for n in presets.preset_names()]


class PLE_OT_lattice_add(SourceAdd, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a PLE lattice rig from a preset, a program (.py), an IR file (.json) or a text block"""

    bl_idname = "ple.lattice_add"
    bl_label = "Add PLE Lattice"
    bl_options = {"REGISTER", "UNDO"}

    source: EnumProperty(name="From", items=[
        ("PRESET", "Preset", "a lattice program shipped with PLE"),
        ("FILE", "File", "a lattice program .py or a data-only IR .json"),
        ("TEXT", "Text Block", "a text block of this file holding a program or an IR")], default="PRESET")
    preset: EnumProperty(name="Preset", items=_preset_items)

    def execute(self, context):
        route = hooks.first("routes", self.preset) if self.source == "PRESET" else None
        if route is not None:  # e.g. a Möbius preset: its frames are Möbius frames
            module, name = route.split(".")
            return getattr(getattr(bpy.ops, module), name)(preset=self.preset)
        try:
            text, kind, default_name, linked, folder = self.source_text()
        except PleError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        try:
            rig = sync.create(context, self.name or default_name, text, kind, tuple(self.region), folder=folder)
        except PleError as exc:
            self.report({"ERROR"}, f"{exc} (the program is kept in text block {text.name!r})")
            return {"CANCELLED"}
        rig.ple.filepath = linked
        select_only(context, rig)
        return {"FINISHED"}


class PLE_OT_program_run(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Run the lattice program again (after editing its text or inputs); trusts it for this session"""

    bl_idname = "ple.program_run"
    bl_label = "Run Program"

    def run(self, context, rig):
        model.trust(rig)
        st = model.state_of(rig)  # keep what was drawn: frame moves made before this still count
        st.program_key, st.topology = (), ()
        done = self.refreshed(rig)
        sliders(rig)
        return done


class PLE_OT_snippet_copy(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Copy the code of the GUI edits (set_u/v/w, add_node, add_beam, ...) to the "PLE snippet"
    text block and the clipboard (thesis §6.2.2, Fig. 6.3)"""

    bl_idname = "ple.snippet_copy"
    bl_label = "Copy Snippet"

    def run(self, context, rig):
        lat = model.lattice_of(rig)
        code = snippets.snippet(model.edits_of(rig), digits=rig.ple.snippet_digits, state=lat)
        text = bpy.data.texts.get(SNIPPET_TEXT) or bpy.data.texts.new(SNIPPET_TEXT)
        text.from_string(code + "\n" if code else "")
        context.window_manager.clipboard = code
        self.report({"INFO"}, f"{len(code.splitlines())} line(s) copied" if code else "no GUI edits to copy")
        return {"FINISHED"}


class PLE_OT_program_apply(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Write the GUI edits into the program text (syntax-tree rewrite keeping comments); re-running
    the program then reproduces the lattice"""

    bl_idname = "ple.program_apply"
    bl_label = "Apply to Program"

    def run(self, context, rig):
        edits = model.edits_of(rig)
        if not edits:
            self.report({"INFO"}, "no GUI edits to apply")
            return {"CANCELLED"}
        text = rig.ple.text
        new = hooks.first("appliers", rig)  # e.g. a CLG rig: its edited pattern into the CLG text
        if new is None and rig.ple.source_kind == "IR":
            new = json.dumps(ir.lattice_to_ir(model.lattice_of(rig), resolved=False), indent=1) + "\n"
        elif new is None:
            if not model.trusted(rig):
                raise PleError("the program is not trusted: press Run Program first")
            source, params = text.as_string(), model.params_of(rig)  # the rewrite runs the program: contained
            new = jobs.call(lambda: snippets.apply_edits(source, edits, params, name=text.name), text.name,
                            "the program")
        text.from_string(new)
        rig.ple.edits = "[]"
        self.report({"INFO"}, f"{len(edits)} edit(s) written into {text.name}")
        return self.refreshed(rig)


class PLE_OT_edits_clear(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Discard the GUI edits not yet applied: back to what the program gives"""

    bl_idname = "ple.edits_clear"
    bl_label = "Discard Edits"

    def run(self, context, rig):
        rig.ple.edits = "[]"
        return self.refreshed(rig)


class PLE_OT_report(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Put a message of live editing into the Info editor (run by the add-on itself)"""

    bl_idname = "ple.report"
    bl_label = "PLE Report"
    bl_options = {"INTERNAL"}

    message: StringProperty(name="Message")

    def execute(self, context):
        self.report({"WARNING"}, self.message)
        return {"FINISHED"}


# ----- everyday actions: remove, duplicate, bake, program file ------------------------------------
class PLE_OT_remove(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Delete the rig: the lattice object, its frames, nodes, cage and region (the program text is kept)"""

    bl_idname = "ple.remove"
    bl_label = "Remove Lattice"

    def run(self, context, rig):
        name = rig.name
        sync.remove(rig)
        self.report({"INFO"}, f"removed {name}")
        return {"FINISHED"}


class PLE_OT_duplicate(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Duplicate the rig with its own copy of the program text and its own trust"""

    bl_idname = "ple.duplicate"
    bl_label = "Duplicate Lattice"

    def run(self, context, rig):
        copy = sync.duplicate(context, rig)
        select_only(context, copy)
        return {"FINISHED"}


class PLE_OT_program_reload(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Read the program again from its file on disk (GUI edits not yet applied are kept)"""

    bl_idname = "ple.program_reload"
    bl_label = "Reload Program"

    def run(self, context, rig):
        path = linked_path(rig)
        try:
            body = path.read_text()
        except OSError as exc:
            raise PleError(f"{path}: cannot read ({exc.strerror})") from None
        old = rig.ple.text.as_string()
        rig.ple.text.from_string(body)
        err = sync.refresh(rig, force=True)
        if err:
            rig.ple.text.from_string(old)
            sync.refresh(rig, force=True)
            raise PleError(f"{path}: {err} (the previous program is kept)")
        sliders(rig)
        self.report({"INFO"}, f"reloaded {path}")
        return {"FINISHED"}


class PLE_OT_program_save(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Write the program text back to its file on disk (atomically: a failed write leaves the file as it was)"""

    bl_idname = "ple.program_save"
    bl_label = "Save Program"

    def run(self, context, rig):
        path = linked_path(rig)
        try:
            with core("io.files").atomic_path(path) as tmp:
                Path(tmp).write_text(rig.ple.text.as_string())
        except OSError as exc:
            raise PleError(f"{path}: cannot write ({exc.strerror})") from None
        self.report({"INFO"}, f"saved {path}")
        return {"FINISHED"}


def sliders(rig) -> None:
    """After the program ran (Run Program, Reload): a slider per input of the program as it now is
    (the user's values kept, ranges and defaults the program's)."""
    inputs = model.state_of(rig).inputs
    if inputs is not None:
        sync.set_params(rig, inputs)


def linked_path(rig) -> Path:
    if not rig.ple.filepath:
        raise PleError("the program is not linked to a file (add the lattice from a .py or .json file)")
    if rig.ple.text is None:
        raise PleError(f"{rig.name}: the program text block is missing")
    return Path(bpy.path.abspath(rig.ple.filepath))




CLASSES = (PLE_OT_lattice_add, PLE_OT_program_run, PLE_OT_snippet_copy, PLE_OT_program_apply, PLE_OT_edits_clear,
           PLE_OT_report, PLE_OT_remove, PLE_OT_duplicate, PLE_OT_program_reload, PLE_OT_program_save)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
