"""What every operator of the add-on shares: acting on a rig (``RigOperator``), reading a source
into a text block (``SourceAdd``), long work as steps that Esc cancels (``SteppedOperator``), the
work budget of meshing, and the base of the sidebar panels (``RigPanel``). Operators translate
Blender state into core calls and core results into Blender data; bad input is reported, never raised.
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, IntVectorProperty, StringProperty

from .. import jobs, prefs
from ..corelink import PleError, files, missing, needs, presets, styles, work
from ..rig import events, model, sync

SNIPPET_TEXT = "PLE snippet"  # the text block snippets go to (and the clipboard)
PROGRESS_BOXES = 20  # a job that asks the core box by box asks about this many boxes (progress steps)


class RigOperator:
    """Acts on the rig named by ``rig`` or on the rig of the active object; a subclass
    defines ``run(context, rig) -> set`` (the operator's work)."""

    bl_options = {"REGISTER", "UNDO"}
    rig: StringProperty(name="Rig", description="Lattice object to act on (default: the active one)")

    def get_rig(self, context):
        obj = bpy.data.objects.get(self.rig) if self.rig else context.active_object
        found = model.rig_of(obj)
        if found is None:
            raise PleError("select a PLE lattice object (or one of its frames)" if not self.rig
                           else f"{self.rig!r} is not a PLE lattice object")
        return found

    @classmethod
    def poll(cls, context):
        """True when the active object belongs to a rig (a rig named by ``rig`` is found even
        if it is not active, but poll cannot see operator properties)."""
        if model.rig_of(getattr(context, "active_object", None)) is not None:
            return True
        cls.poll_message_set("select a PLE lattice object (or one of its frames)")
        return False

    def execute(self, context):
        try:
            rig = self.get_rig(context)
        except (PleError, ModuleNotFoundError) as exc:
            exc = _reported(exc)
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        try:
            return self.run(context, rig)
        except (PleError, ModuleNotFoundError) as exc:
            exc = _reported(exc)
            rig.ple.status = str(exc)  # the panel's status line as well as the Info report
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}

    def set_filter(self, rig, **settings) -> set:
        """Set filter settings and redraw; on error the previous settings come back."""
        err = events.apply_filter(rig, settings)
        if err:
            self.report({"ERROR"}, err)
            return {"CANCELLED"}
        return {"FINISHED"}

    def refreshed(self, rig) -> set:
        err = sync.refresh(rig, force=True)
        if err:
            self.report({"ERROR"}, err)
            return {"CANCELLED"}
        return {"FINISHED"}


class SourceAdd:
    """What the Add operators share (a lattice, a CLG): the source chosen (a preset, a file, a text
    block) read into a Text datablock. ``preset_file()`` resolves the preset; ``what`` names the
    kinds of file accepted in the error message."""

    what = ".py program or .json IR file"
    filepath: StringProperty(name="File", subtype="FILE_PATH")
    text: StringProperty(name="Text Block")
    name: StringProperty(name="Name", description="Name of the new object (default: the source's)")
    region: IntVectorProperty(name="Region", size=3, min=1, default=(3, 3, 3),
                              description="Node-groups per direction drawn in full")

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
        """(Text datablock, kind, default name, file on disk or "", folder a body mesh resolves
        against or ""); a new Text for presets and files."""
        if self.source == "TEXT":
            text = bpy.data.texts.get(self.text)
            if text is None:
                raise PleError(f"no text block named {self.text!r}")
            kind = "IR" if text.as_string().lstrip().startswith("{") else "PROGRAM"
            return text, kind, Path(text.name).stem, "", ""
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
        return text, ("IR" if path.suffix == ".json" else "PROGRAM"), path.stem, linked, str(path.parent)


MESH_FILES = (".stl", ".3mf", ".ply", ".obj", ".glb")


def output_path(filepath: str, suffixes=MESH_FILES) -> Path:
    """The file an operator writes (Blender's relative paths resolved); PleError unless its suffix
    is one of ``suffixes``."""
    path = Path(bpy.path.abspath(filepath))
    if path.suffix.lower() not in suffixes:
        raise PleError(f"{filepath!r}: choose a {', '.join(suffixes[:-1])} or {suffixes[-1]} file"
                       if len(suffixes) > 1 else f"{filepath!r}: choose a {suffixes[0]} file")
    return path


def draw_source_menu(layout, operator: str, names, icon: str, icon_of=None) -> None:
    """An Add menu: one entry per preset ``names`` (with ``icon_of(name)``'s thumbnail if it has
    one), then *From File…*."""
    for name in names:
        value = icon_of(name) if icon_of is not None else 0
        op = layout.operator(operator, text=name, **({"icon_value": value} if value else {"icon": icon}))
        op.source, op.preset = "PRESET", name
    layout.separator()
    layout.operator(operator, text="From File…", icon="FILE_SCRIPT").source = "FILE"


def select_only(context, obj) -> None:
    """Make ``obj`` the only selected and the active object (a new rig, a copy)."""
    for other in context.view_layer.objects:
        other.select_set(False)
    context.view_layer.objects.active = obj
    obj.select_set(True)


# ----- long operations: tessellate and export ---------------------------------------------------
def _style_item(s) -> tuple[str, str, str]:
    return s.name.upper().replace("-", "_"), s.label, s.description


EXPORT_STYLES = [_style_item(s) for s in styles.STYLES.values()]  # the core's registry of styles
STYLES = [_style_item(s) for s in styles.STYLES.values() if s.solid]


def core_style(style: str) -> str:
    return style.lower().replace("_", "-")


def budget(lat, region, style: str, what: str, streamed: bool = False, beyond: bool = False):
    """Refuse work beyond the add-on preferences' limits, with the core's one estimate of a mesh
    (``ple.app.pipeline.estimate``, as ``ple mesh``'s), unless the user said to go ``beyond``
    them. A streamed STL export holds one box at a time: only its triangle count is limited."""
    pipeline = needs("app.pipeline")  # trimesh and manifold3d: bundled wheels
    plan = pipeline.plan(pipeline.MeshRequest(lat, region, core_style(style)))
    est = pipeline.estimate(plan, "stl" if streamed else "memory").work
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
        except (PleError, ModuleNotFoundError) as exc:
            exc = _reported(exc)
            self.fail(context, str(exc))
            return {"CANCELLED"}
        self.done(context)
        return {"FINISHED"}

    def fail(self, context, message: str) -> None:
        """Report to the Info editor and to the rig's status line (the panel)."""
        self.report({"ERROR"}, message)
        found = model.rig_of(bpy.data.objects.get(self.rig) if self.rig else context.active_object)
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
        except (PleError, ModuleNotFoundError) as exc:
            exc = _reported(exc)
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
        except (PleError, ModuleNotFoundError) as exc:
            exc = _reported(exc)
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

    def mesh_job(self, request, folder: Path):
        """Steps meshing ``request`` (``ple.app.pipeline.mesh_steps``) in a child process, box by
        box; the child welds the boxes and leaves the arrays in ``folder``, which this process
        maps (Blender's mesh is then the only copy it holds). Returns (vertices (V, 3) float32,
        faces (F, 3) int32, both mapped from ``folder``, the unclean-hubs line or None)."""
        pipeline = needs("app.pipeline")  # trimesh and manifold3d: bundled wheels
        p = pipeline.plan(request)

        def work():
            info: dict = {}
            verts, faces = yield from pipeline.mesh_steps(p, info)
            np.save(folder / "vertices.npy", verts)
            np.save(folder / "faces.npy", faces)
            return unclean_line(info)

        job = jobs.start(work, self._rig.name, p.describe(), self.beyond_limit)
        _, line = yield from jobs.follow(job, lambda items: 0.8 * (items[-1] if items else 0.0))
        return np.load(folder / "vertices.npy", mmap_mode="r"), np.load(folder / "faces.npy", mmap_mode="r"), line

    def file_job(self, request, path):
        """Steps writing ``request``'s mesh to ``path`` in a child process (``pipeline.write_mesh``,
        as ``ple mesh``); returns (triangles written, the unclean-hubs line or None). The child
        writes a temporary beside ``path``, and this process renames it over ``path`` only once
        the job is complete: a child that finishes while Esc stops it leaves nothing behind."""
        pipeline = needs("app.pipeline")
        folder = None
        try:
            with files.atomic_path(path) as tmp:
                folder = tmp.parent

                def work():
                    info: dict = {}
                    n = pipeline.write_mesh(request, tmp, info)
                    return n, unclean_line(info)

                job = jobs.start(work, self._rig.name, f"the export of region {request.region}", self.beyond_limit)
                _, (count, line) = yield from jobs.follow(job, lambda items: 0.5)
        finally:  # a child killed mid-write leaves its own temporary: its tree is gone by now
            if folder is not None:
                files.remove_stale_temporaries(folder)
        return count, line


def unclean_line(info: dict):
    """The report line of the unclean hubs a mesh united (None: clean or not checked)."""
    rep = info.get("unclean")
    return rep.line() if rep is not None and len(rep.nodes) else None


class RigPanel:
    """A sidebar panel (3D viewport › PLE) about the rig of the active object."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "PLE"

    @classmethod
    def poll(cls, context):
        return model.rig_of(context.active_object) is not None

    def rig(self, context):
        return model.rig_of(context.active_object)


def register() -> None:
    pass


def unregister() -> None:
    pass


def _reported(exc: Exception) -> PleError:
    """The error an operator reports: a package Blender's Python lacks is named, not a traceback."""
    return missing(exc) if isinstance(exc, ModuleNotFoundError) else exc
