"""Operators (idnames are public API, SPEC §7). Each one translates Blender state into core
calls and core results into Blender data; bad input is reported, never raised."""

from __future__ import annotations

import json
from pathlib import Path

import bpy
import numpy as np
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    IntVectorProperty,
    StringProperty,
)

from . import jobs, mobius_frames, prefs
from . import rig as rigmod
from .corelink import PleError, core, ir, needs, presets, snippets, styles, work

SNIPPET_TEXT = "PLE snippet"
EXPORT_BOXES = 20  # an STL export streams the region in about this many boxes (progress steps)


def _preset_items(self, context):
    return [(n, n, presets.preset_description(n)) for n in presets.preset_names()]


class RigOperator:
    """Acts on the rig named by ``rig`` or on the rig of the active object; a subclass
    defines ``run(context, rig) -> set`` (the operator's work)."""

    bl_options = {"REGISTER", "UNDO"}
    rig: StringProperty(name="Rig", description="Lattice object to act on (default: the active one)")

    def get_rig(self, context):
        obj = bpy.data.objects.get(self.rig) if self.rig else context.active_object
        found = rigmod.rig_of(obj)
        if found is None:
            raise PleError("select a PLE lattice object (or one of its frames)" if not self.rig
                           else f"{self.rig!r} is not a PLE lattice object")
        return found

    @classmethod
    def poll(cls, context):
        """True when the active object belongs to a rig (a rig named by ``rig`` is found even
        if it is not active, but poll cannot see operator properties)."""
        if rigmod.rig_of(getattr(context, "active_object", None)) is not None:
            return True
        cls.poll_message_set("select a PLE lattice object (or one of its frames)")
        return False

    def execute(self, context):
        try:
            rig = self.get_rig(context)
        except PleError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        try:
            return self.run(context, rig)
        except PleError as exc:
            rig.ple.status = str(exc)  # the panel's status line as well as the Info report
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}

    def set_filter(self, rig, **settings) -> set:
        """Set filter settings and redraw; on error the previous settings come back."""
        err = rigmod.apply_filter(rig, settings)
        if err:
            self.report({"ERROR"}, err)
            return {"CANCELLED"}
        return {"FINISHED"}

    def refreshed(self, rig) -> set:
        err = rigmod.refresh(rig, force=True)
        if err:
            self.report({"ERROR"}, err)
            return {"CANCELLED"}
        return {"FINISHED"}


class SourceAdd:
    """What the Add operators share (a lattice, a CLG): the source chosen (a preset, a file, a text
    block) read into a Text datablock. ``preset_file()`` resolves the preset; ``what`` names the
    kinds of file accepted in the error message."""

    what = ".py program or .json IR file"

    def preset_file(self) -> Path:
        path = presets.preset_path(self.preset)
        if path is None:
            raise PleError(f"unknown preset {self.preset!r}")
        return path

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def invoke(self, context, event):
        if self.source == "FILE" and not self.filepath:
            context.window_manager.fileselect_add(self)
            return {"RUNNING_MODAL"}
        return context.window_manager.invoke_props_dialog(self)

    def source_text(self):
        """(Text datablock, kind, default name, file on disk or ""); a new Text for presets and files."""
        if self.source == "TEXT":
            text = bpy.data.texts.get(self.text)
            if text is None:
                raise PleError(f"no text block named {self.text!r}")
            kind = "IR" if text.as_string().lstrip().startswith("{") else "PROGRAM"
            return text, kind, Path(text.name).stem, ""
        if self.source == "PRESET":
            path = self.preset_file()
        else:
            path = Path(bpy.path.abspath(self.filepath))
            if path.suffix not in (".py", ".json") or not path.is_file():
                raise PleError(f"{self.filepath!r}: expected an existing {self.what}")
        try:
            body = path.read_text()
        except OSError as exc:
            raise PleError(f"{path}: cannot read ({exc.strerror})") from None
        text = bpy.data.texts.new(path.name)
        text.from_string(body)
        linked = str(path) if self.source == "FILE" else ""  # a preset is not the user's file
        return text, ("IR" if path.suffix == ".json" else "PROGRAM"), path.stem, linked


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
    filepath: StringProperty(name="File", subtype="FILE_PATH")
    text: StringProperty(name="Text Block")
    name: StringProperty(name="Name", description="Name of the lattice object (default: the source's)")
    region: IntVectorProperty(name="Region", size=3, min=1, default=(3, 3, 3),
                              description="Node-groups per direction drawn in full")

    def execute(self, context):
        if self.source == "PRESET" and self.preset in mobius_frames.PRESETS:  # its frames are Möbius frames
            return bpy.ops.ple.mobius_add(preset=self.preset)
        try:
            text, kind, default_name, linked = self.source_text()
        except PleError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        try:
            rig = rigmod.create(context, self.name or default_name, text, kind, tuple(self.region))
        except PleError as exc:
            self.report({"ERROR"}, f"{exc} (the program is kept in text block {text.name!r})")
            return {"CANCELLED"}
        rig.ple.filepath = linked
        select_only(context, rig)
        return {"FINISHED"}


def select_only(context, obj) -> None:
    """Make ``obj`` the only selected and the active object (a new rig, a copy)."""
    for other in context.view_layer.objects:
        other.select_set(False)
    context.view_layer.objects.active = obj
    obj.select_set(True)


class PLE_OT_program_run(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Run the lattice program again (after editing its text or inputs); trusts it for this session"""

    bl_idname = "ple.program_run"
    bl_label = "Run Program"

    def run(self, context, rig):
        rigmod.trust(rig)
        st = rigmod.state_of(rig)  # keep what was drawn: frame moves made before this still count
        st.program_key, st.topology = (), ()
        return self.refreshed(rig)


class PLE_OT_snippet_copy(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Copy the code of the GUI edits (set_u/v/w, add_node, add_beam, ...) to the "PLE snippet"
    text block and the clipboard (thesis §6.2.2, Fig. 6.3)"""

    bl_idname = "ple.snippet_copy"
    bl_label = "Copy Snippet"

    def run(self, context, rig):
        lat = rigmod.lattice_of(rig)
        code = snippets.snippet(rigmod.edits_of(rig), digits=rig.ple.snippet_digits, state=lat)
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
        edits = rigmod.edits_of(rig)
        if not edits:
            self.report({"INFO"}, "no GUI edits to apply")
            return {"CANCELLED"}
        text = rig.ple.text
        if rig.ple_clg.active:  # a CLG rig: its edited pattern into the CLG text (clg_rig.py)
            from . import clg_rig

            new = clg_rig.applied_text(rig)
        elif rig.ple.source_kind == "IR":
            lat = rigmod.lattice_of(rig)
            new = json.dumps(ir.lattice_to_ir(lat, resolved=False), indent=1) + "\n"
        else:
            if not rigmod.trusted(rig):
                raise PleError("the program is not trusted: press Run Program first")
            source, params = text.as_string(), rigmod.params_of(rig)  # the rewrite runs the program: contained
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


class PLE_OT_node_add(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a node (ball) to the template node-group N[0,0,0]"""

    bl_idname = "ple.node_add"
    bl_label = "Add Template Node"

    center: FloatVectorProperty(name="Centre", size=3, description="Centre in the placement frame")
    radius: FloatProperty(name="Radius", min=1e-6, default=0.05, description="Ball radius")

    def run(self, context, rig):
        rigmod.add_edits(rig, [snippets.AddNode(tuple(self.center), self.radius)])
        return self.refreshed(rig)


def _selected_nodes(context, rig) -> list[int]:
    sel = [o for o in context.selected_objects if o.ple.role == "NODE" and o.ple.rig == rig]
    act = context.active_object
    sel.sort(key=lambda o: o != act)  # the active node first
    return [o.ple.node_index for o in sel]


class PLE_OT_node_remove(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Remove a template node and every beam-pattern using it"""

    bl_idname = "ple.node_remove"
    bl_label = "Remove Template Node"

    index: IntProperty(name="Node", default=-1, min=-1, description="Template node index (-1: the active node)")

    def run(self, context, rig):
        idx = self.index if self.index >= 0 else next(iter(_selected_nodes(context, rig)), -1)
        if idx < 0:
            raise PleError("select a template node (sphere empty) or give its index")
        lat = rigmod.lattice_of(rig)
        if len(lat.nodes) <= 1:
            raise PleError("the template node-group needs at least one node")
        snippets.apply_to_lattice(lat, [snippets.RemoveNode(idx)])  # validates before recording
        rigmod.add_edits(rig, [snippets.RemoveNode(idx)])
        return self.refreshed(rig)


class PLE_OT_beam_add(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a beam-pattern joining node n1 of group (i, j, k) to node n2 of group (i+di, j+dj, k+dk)"""

    bl_idname = "ple.beam_add"
    bl_label = "Add Beam-Pattern"

    n1: IntProperty(name="From node", default=-1, min=-1, description="-1: the active selected node")
    n2: IntProperty(name="To node", default=-1, min=-1, description="-1: the other selected node")
    offset: IntVectorProperty(name="Offset", size=3, default=(1, 0, 0), description="(di, dj, dk)")

    def run(self, context, rig):
        sel = _selected_nodes(context, rig)
        n1 = self.n1 if self.n1 >= 0 else (sel[0] if sel else -1)
        n2 = self.n2 if self.n2 >= 0 else (sel[1] if len(sel) > 1 else n1)
        if n1 < 0:
            raise PleError("pick two template nodes (or one, for a beam to its own copy) or give n1, n2")
        edit = snippets.AddBeam(n1, n2, *self.offset)
        snippets.apply_to_lattice(rigmod.lattice_of(rig), [edit])  # validates before recording
        rigmod.add_edits(rig, [edit])
        return self.refreshed(rig)


class PLE_OT_beam_remove(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Remove beam-pattern number ``index``"""

    bl_idname = "ple.beam_remove"
    bl_label = "Remove Beam-Pattern"

    index: IntProperty(name="Beam-pattern", min=0)

    def run(self, context, rig):
        edit = snippets.RemoveBeam(self.index)
        snippets.apply_to_lattice(rigmod.lattice_of(rig), [edit])
        rigmod.add_edits(rig, [edit])
        return self.refreshed(rig)


class PLE_OT_stencil_filter(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Index stencil filter (thesis §9): keep node-group (i, j, k) where the stencil at
    (i, j, k) modulo its shape is 1"""

    bl_idname = "ple.stencil_filter"
    bl_label = "Stencil Filter"

    shape: IntVectorProperty(name="Shape", size=3, min=1, max=16, default=(2, 2, 2))
    bits: StringProperty(name="Stencil", default="10010110", description="0/1 per cell, (i, j, k) order, k fastest")
    clear: bpy.props.BoolProperty(name="Clear", default=False, description="Remove the rig's filter")

    def run(self, context, rig):
        if self.clear:
            rig.ple.filter_kind = "NONE"
            return self.refreshed(rig)
        n = int(np.prod(tuple(self.shape)))
        if len(self.bits) != n or set(self.bits) - {"0", "1"}:
            raise PleError(f"stencil: expected {n} characters 0/1 for shape {tuple(self.shape)}, got {self.bits!r}")
        return self.set_filter(rig, stencil_shape=tuple(self.shape), stencil_bits=self.bits, filter_kind="STENCIL")


# ----- long operations: tessellate and export ---------------------------------------------------
def _style_item(s) -> tuple[str, str, str]:
    return s.name.upper().replace("-", "_"), s.label, s.description


EXPORT_STYLES = [_style_item(s) for s in styles.STYLES.values()]  # the core's registry of styles
STYLES = [_style_item(s) for s in styles.STYLES.values() if s.solid]


def core_style(style: str) -> str:
    return style.lower().replace("_", "-")


def mesh_from_arrays(name: str, verts, faces, me=None):
    """A mesh of vertices (n, 3) and faces (f, k) of k corners each (a new one, or ``me`` refilled)."""
    if me is None:
        me = bpy.data.meshes.new(name)
    else:
        me.clear_geometry()
    k = faces.shape[1] if len(faces) else 3
    me.vertices.add(len(verts))
    me.loops.add(k * len(faces))
    me.polygons.add(len(faces))
    me.attributes["position"].data.foreach_set("vector", verts.astype(np.float32).ravel())
    me.attributes[".corner_vert"].data.foreach_set("value", faces.astype(np.int32).ravel())
    me.polygons.foreach_set("loop_start", np.arange(0, k * len(faces), k, dtype=np.int32))
    me.update(calc_edges=True)
    return me


def budget(lat, region, style: str, what: str, streamed: bool = False, beyond: bool = False):
    """Refuse work beyond the add-on preferences' limits, with the estimate
    (``meshing.styles.mesh_estimate``), unless the user said to go ``beyond`` them. A streamed
    STL export holds one box at a time: only its triangle count is limited."""
    est = styles.mesh_estimate(lat, region, core_style(style))
    if beyond:
        return est
    return work.check(est, max_bytes=None if streamed else prefs.max_bytes(),
                       max_triangles=prefs.get("max_triangles"), what=what)


BEYOND = BoolProperty(name="Beyond the limit", default=False, options={"SKIP_SAVE"},
                      description="Run even if the work estimate exceeds the limits of the add-on preferences "
                                  "(invoked from the UI, PLE asks first)")


class SteppedOperator(RigOperator):
    """Long work as steps: a subclass defines the generator ``steps(context, rig)`` yielding
    progress fractions (its core work runs contained in a child process, ``jobs.follow``) and
    sets ``self.result`` to the message it ends with; ``execute`` runs them all; ``invoke``
    (with a window) runs one step per timer tick, so that Esc cancels at any moment. Progress
    and the result go to the panel (``rig.ple.message``) and, while running, the status bar."""

    _steps = None
    _timer = None
    _rig = None
    _confirmed = False  # the user answered "Run anyway" (invoke_confirm then calls execute)
    result = ""

    def execute(self, context):
        if self._confirmed and context.window is not None and not bpy.app.background:
            # confirmed "Run anyway" (invoke_confirm calls execute): run as the modal job, so that
            # Esc still cancels it; invoke passes the budget step since beyond_limit is set
            op = getattr(getattr(bpy.ops, self.bl_idname.split(".")[0]), self.bl_idname.split(".")[1])
            return op("INVOKE_DEFAULT", **self.as_keywords())
        wm = context.window_manager
        try:
            self._rig = self.get_rig(context)
            gen = self.steps(context, self._rig)
            wm.progress_begin(0, 100)
            try:
                for frac in gen:
                    wm.progress_update(int(100 * frac))
            finally:
                wm.progress_end()
        except PleError as exc:
            self.fail(context, str(exc))
            return {"CANCELLED"}
        self.done(context)
        return {"FINISHED"}

    def fail(self, context, message: str) -> None:
        """Report to the Info editor and to the rig's status line (the panel)."""
        self.report({"ERROR"}, message)
        found = rigmod.rig_of(bpy.data.objects.get(self.rig) if self.rig else context.active_object)
        if found is not None:
            found.ple.status = message
            found.ple.message = f"{self.bl_label}: failed"

    def done(self, context) -> None:
        if self.result:
            self.report({"INFO"}, self.result)
            self._rig.ple.message = self.result

    def invoke(self, context, event):
        if context.window is None or bpy.app.background:
            return self.execute(context)
        try:
            self._rig = self.get_rig(context)
            self._steps = self.steps(context, self._rig)
            next(self._steps)  # the first step checks the work budget
        except StopIteration:
            self.done(context)
            return {"FINISHED"}
        except PleError as exc:
            if "refused" in str(exc) and not self.beyond_limit:  # ask: beyond the limit?
                self.beyond_limit = self._confirmed = True
                return context.window_manager.invoke_confirm(self, event, title="Beyond the work limit",
                                                             message=str(exc), confirm_text="Run anyway",
                                                             icon="WARNING")
            self.fail(context, str(exc))
            return {"CANCELLED"}
        wm = context.window_manager
        wm.progress_begin(0, 100)
        self._timer = wm.event_timer_add(jobs.TICK, window=context.window)
        wm.modal_handler_add(self)
        self.show(context, 0.0)
        return {"RUNNING_MODAL"}

    def show(self, context, frac: float) -> None:
        """Progress in the cursor, the status bar and the panel."""
        context.window_manager.progress_update(int(100 * frac))
        text = f"{self.bl_label}: {100 * frac:.0f} % (Esc cancels)"
        self._rig.ple.message = text
        if context.workspace is not None:
            context.workspace.status_text_set(text)
        for area in context.screen.areas if context.screen is not None else ():
            if area.type == "VIEW_3D":
                area.tag_redraw()

    def modal(self, context, event):
        if event.type == "ESC":
            self._steps.close()  # stops the child: nothing of the job is applied
            self.finish(context)
            self._rig.ple.message = f"{self.bl_label}: cancelled, nothing changed"
            self.report({"WARNING"}, self._rig.ple.message)
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        try:
            self.show(context, next(self._steps))
        except StopIteration:
            self.finish(context)
            self.done(context)
            return {"FINISHED"}
        except PleError as exc:
            self.finish(context)
            self.fail(context, str(exc))
            return {"CANCELLED"}
        return {"RUNNING_MODAL"}

    def finish(self, context):
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
        wm.progress_end()
        if context.workspace is not None:
            context.workspace.status_text_set(None)

    def mesh_job(self, lat, region, style: str):
        """Steps tessellating ``region`` box by box in a child process (thesis §6.2.2 hubs per
        box); returns the boxes (vertices, faces)."""
        tess = needs("meshing.tessellate")
        size = max(1, region.groups // EXPORT_BOXES)
        boxes = len(range(0, region.groups, size))
        job = jobs.start(lambda: tess.iter_triangles(lat, region, core_style(style), max_groups=size),
                         self._rig.name, f"the {core_style(style)} tessellation of {region}", self.beyond_limit)
        chunks, _ = yield from jobs.follow(job, lambda items: 0.8 * min(1.0, len(items) / boxes))
        return chunks


class PLE_OT_tessellate(SteppedOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Tessellate the drawn region into a new mesh object (CHoCC, CNT or refined, CHoCC paper)"""

    bl_idname = "ple.tessellate"
    bl_label = "Tessellate Region"

    style: EnumProperty(name="Style", items=STYLES, default="CHOCC")
    beyond_limit: BEYOND

    def steps(self, context, rig):
        self._rig = rig
        lat = rigmod.shown_lattice(rig)  # the panel's filter too: what is drawn is what is meshed
        region = rigmod.region_of(rig, lat)
        if region is None:
            raise PleError("the region is empty: set Region from/to inside the repetition counts")
        budget(lat, region, self.style, f"{self.style.lower()} tessellation of {region}",
               beyond=self.beyond_limit)
        yield 0.0
        chunks = yield from self.mesh_job(lat, region, self.style)
        verts, faces = needs("meshing.tessellate").weld_chunks(chunks)  # welded by the core
        yield 0.8
        me = mesh_from_arrays(f"{rig.name}.{self.style.lower()}", verts, faces)
        obj = bpy.data.objects.new(me.name, me)
        for coll in rig.users_collection:
            coll.objects.link(obj)
        obj.matrix_world = rig.matrix_world
        self.result = f"{obj.name}: {len(faces)} triangles"
        yield 1.0


class PLE_OT_export(SteppedOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
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
        path = Path(bpy.path.abspath(self.filepath))
        if path.suffix.lower() not in (".stl", ".3mf", ".ply", ".obj", ".glb"):
            raise PleError(f"{self.filepath!r}: choose a .stl, .3mf, .ply, .obj or .glb file")
        lat = rigmod.shown_lattice(rig)  # the panel's filter too: what is drawn is what is meshed
        region = rigmod.region_of(rig, lat)
        if region is None:
            raise PleError("the region is empty: set Region from/to inside the repetition counts")
        tess, export = needs("meshing.tessellate"), needs("io.export")
        streamed = path.suffix.lower() == ".stl"
        budget(lat, region, self.style, f"export of {region}", streamed=streamed, beyond=self.beyond_limit)
        yield 0.0
        # binary STL is snapped to the region's float32 grid as `ple mesh` writes it (previews are
        # not snapped); other formats are welded into one mesh by the core
        chunks = yield from self.mesh_job(lat, region, self.style)
        yield 0.8
        if streamed:
            grid = None if core_style(self.style) == "balls-beams" else tess.output_grid(lat, region)
            count = export.write_stl(path, chunks, header=export.stl_header(), grid=grid)
        else:
            count = export.write_chunks(path, chunks)
        self.result = f"{count} triangles written to {path}"
        yield 1.0


class PLE_OT_lil_filter(SteppedOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Lattice-in-Lattice filter (thesis §9): draw only the nodes of the region whose balls
    interfere with a coarse PLE lattice (a job: progress, Esc cancels, the rig changes only
    when it is complete)"""

    bl_idname = "ple.lil_filter"
    bl_label = "LiL Filter"

    coarse: StringProperty(name="Coarse", description="Coarse PLE lattice object (default: another selected one)")
    beyond_limit: BEYOND

    def steps(self, context, rig):
        self._rig = rig
        coarse = bpy.data.objects.get(self.coarse) if self.coarse else next(
            (o for o in context.selected_objects if rigmod.is_rig(o) and o != rig), None)
        if not rigmod.is_rig(coarse) or coarse == rig:
            raise PleError("LiL filter: give (or select) another PLE lattice object as the coarse lattice")
        lat = rigmod.lattice_of(rig)
        shown = lat.with_filter(rigmod.lil_filter(rig, coarse))
        region = rigmod.region_of(rig, lat)
        if region is None:
            raise PleError("the region is empty: set Region from/to inside the repetition counts")
        if not self.beyond_limit:
            work.check(work.estimate(lat, region), max_bytes=prefs.max_bytes(), what=f"LiL filter of region {region}")
        key = rigmod.lil_key(rig, coarse)
        yield 0.0
        size = max(1, region.groups // EXPORT_BOXES)  # the filter is asked box by box: progress
        job = jobs.start(lambda: shown.evaluate_steps(region, max_groups=size), rig.name,
                         f"the LiL filter of region {region}", self.beyond_limit)
        _, ev = yield from jobs.follow(job, lambda items: 0.95 * (items[-1] if items else 0.0))
        # drawn only if nothing it depends on changed meanwhile (else evaluated again, contained)
        prepared = (lat, ev) if rigmod.lil_key(rig, coarse) == key else None
        err = rigmod.apply_filter(rig, {"coarse": coarse, "filter_kind": "LIL"}, prepared)
        if err:
            raise PleError(err)
        kept, total = len(ev.center), region.groups * len(lat.nodes)
        self.result = f"LiL filter by {coarse.name}: {kept} of {total} balls of region {region} kept"
        yield 1.0


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
        rigmod.remove(rig)
        self.report({"INFO"}, f"removed {name}")
        return {"FINISHED"}


class PLE_OT_duplicate(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Duplicate the rig with its own copy of the program text and its own trust"""

    bl_idname = "ple.duplicate"
    bl_label = "Duplicate Lattice"

    def run(self, context, rig):
        copy = rigmod.duplicate(context, rig)
        select_only(context, copy)
        return {"FINISHED"}


class PLE_OT_bake(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Freeze the drawn region (balls and beams as Blender draws them) into a plain mesh object"""

    bl_idname = "ple.bake"
    bl_label = "Bake Region"

    def run(self, context, rig):
        region = rigmod.parts(rig).get("region")
        if region is None or not len(region.data.vertices):
            raise PleError("nothing to bake: the region is empty")
        depsgraph = context.evaluated_depsgraph_get()
        me = bpy.data.meshes.new_from_object(region.evaluated_get(depsgraph), preserve_all_data_layers=False,
                                             depsgraph=depsgraph)
        me.name = f"{rig.name}.baked"
        obj = bpy.data.objects.new(me.name, me)
        coll = context.scene.collection
        coll.objects.link(obj)
        obj.matrix_world = region.matrix_world
        self.report({"INFO"}, f"{obj.name}: {len(me.polygons)} faces")
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
        err = rigmod.refresh(rig, force=True)
        if err:
            rig.ple.text.from_string(old)
            rigmod.refresh(rig, force=True)
            raise PleError(f"{path}: {err} (the previous program is kept)")
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


def linked_path(rig) -> Path:
    if not rig.ple.filepath:
        raise PleError("the program is not linked to a file (add the lattice from a .py or .json file)")
    if rig.ple.text is None:
        raise PleError(f"{rig.name}: the program text block is missing")
    return Path(bpy.path.abspath(rig.ple.filepath))


CLASSES = (PLE_OT_lattice_add, PLE_OT_program_run, PLE_OT_snippet_copy, PLE_OT_program_apply, PLE_OT_edits_clear,
           PLE_OT_node_add, PLE_OT_node_remove, PLE_OT_beam_add, PLE_OT_beam_remove, PLE_OT_lil_filter,
           PLE_OT_stencil_filter, PLE_OT_tessellate, PLE_OT_export, PLE_OT_remove, PLE_OT_duplicate, PLE_OT_bake,
           PLE_OT_program_reload, PLE_OT_program_save, PLE_OT_report)
