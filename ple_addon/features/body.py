"""The Body panel: a lattice that fills a Blender mesh object (docs/body.md, docs/addon.md).

The settings (``obj.ple_body`` on the lattice object) pick the body object, the fill mode
(inside, centroid, any), the skin thickness, the cleanup and the graded thickness (a gradient
between two empties, or by the distance to the body's surface). Nothing here computes geometry:
the body object's mesh goes to the core as arrays (``foreach_get``) with its transform relative
to the rig as the body's placement, and ``fill`` turns the settings into core objects (a radius
field, a ``BodyFilter``, a cleanup) on the rig's lattice, so drawing, tessellation and export
evaluate the same kept set. Moving the body or a gradient empty redraws the rigs using it.
"""

from __future__ import annotations

import importlib.util

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, PointerProperty, StringProperty

from .. import draw
from ..corelink import PleError, Similarity, body, cleanup, grading, needs, weld
from ..ops.base import RigPanel
from ..rig import events, hooks, model, sync
from ..session import SESSION

FILL_MODES = [("INSIDE", "Inside", "keep balls wholly inside the body (beams where both balls are kept)"),
              ("CENTROID", "Centroid", "keep whole node-groups whose template centroid is inside"),
              ("ANY", "Any", "keep balls touching the body; meshes are cut at its surface")]
GRADES = [("NONE", "None", "constant thickness"),
          ("LINEAR", "Gradient", "radii times Factor A at empty A to Factor B at empty B, linear between"),
          ("SURFACE", "Surface", "radii times Factor A on the body's surface to Factor B at Depth inside")]
SIMILARITY_TOL = 1e-5  # a body transform within this of a similarity is used as its placement
BODIES_KEPT = 4  # core Bodies cached (by mesh contents and placement)


def _changed(self, context):
    events.on_settings_changed(self.id_data)


def _is_mesh(self, obj):
    return obj.type == "MESH" and obj.ple.role == "NONE"


def _is_empty(self, obj):
    return obj.type == "EMPTY" and obj.ple.role == "NONE"


class PLE_BodySettings(bpy.types.PropertyGroup):  # noqa: N801 - Blender naming
    body: PointerProperty(name="Body", type=bpy.types.Object, poll=_is_mesh, update=_changed,
                          description="A closed mesh object the lattice fills (its own transform places it)")
    fill: EnumProperty(name="Fill", items=FILL_MODES, default="INSIDE", update=_changed)
    open_winding: BoolProperty(name="Open mesh: winding numbers", default=False, update=_changed,
                               description="Test an open mesh by generalized winding numbers instead of refusing it")
    skin: FloatProperty(name="Skin", min=0.0, default=0.0, precision=4, update=_changed,
                        description="Thickness of the shell inside the body (0: no skin); Skin Solid unites it "
                                    "with the lattice")
    cleanup: BoolProperty(name="Cleanup", default=False, update=_changed,
                          description="Remove dangling balls (degree <= 1, repeatedly) and every piece but the largest")
    keep_skin: BoolProperty(name="Keep beams on the skin", default=True, update=_changed,
                            description="With a skin: balls reaching into the skin are held by it (not dangling)")
    grade: EnumProperty(name="Grade", items=GRADES, default="NONE", update=_changed)
    grade_a: PointerProperty(name="Empty A", type=bpy.types.Object, poll=_is_empty, update=_changed)
    grade_b: PointerProperty(name="Empty B", type=bpy.types.Object, poll=_is_empty, update=_changed)
    factor_a: FloatProperty(name="Factor A", min=1e-3, default=1.0, update=_changed)
    factor_b: FloatProperty(name="Factor B", min=1e-3, default=2.0, update=_changed)
    depth: FloatProperty(name="Depth", min=1e-6, default=1.0, update=_changed,
                         description="Surface grade: distance from the surface where Factor B is reached")


# ----- Blender data -> core arrays ------------------------------------------------------------------
def mesh_arrays(obj) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) in the object's own coordinates and triangles (F, 3) of a mesh object's
    data (its loop triangles: n-gons split as Blender draws them; modifiers not applied)."""
    me = obj.data
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    me.calc_loop_triangles()
    tris = np.zeros(len(me.loop_triangles) * 3, np.int32)
    me.loop_triangles.foreach_get("vertices", tris)
    return co.reshape(-1, 3).astype(float), tris.reshape(-1, 3).astype(np.int64)


def relative(rig, obj) -> np.ndarray:
    """The 4x4 matrix taking ``obj``'s coordinates into the rig's (the lattice's) coordinates."""
    return np.array(rig.matrix_world.inverted() @ obj.matrix_world, dtype=float)


def body_of(rig, settings):
    """The core Body of the panel's body object, placed by its transform relative to the rig: a
    similarity is the body's placement; any other affine map (a non-uniform scale) is applied to
    the vertices. Cached by mesh contents and placement."""
    obj = settings.body
    if obj is None:
        raise PleError("Body: choose a mesh object")
    verts, tris = mesh_arrays(obj)
    m = relative(rig, obj)
    opened = "winding" if settings.open_winding else "error"
    key = (obj.name, verts.tobytes(), tris.tobytes(), m.round(9).tobytes(), opened)
    bodies = SESSION.cache("bodies")
    found = bodies.get(key)
    if found is not None:
        return found
    placement = None
    try:
        placement = Similarity.from_matrix(m)
    except PleError:
        pass
    if placement is None or not np.allclose(placement.matrix, m, atol=SIMILARITY_TOL * max(1.0, np.abs(m).max())):
        verts, placement = verts @ m[:3, :3].T + m[:3, 3], None
    _needs_package("scipy", "filling a body")
    made = body.Body(verts, tris, placement, open=opened, name=f"body {obj.name}")
    if len(bodies) >= BODIES_KEPT:
        bodies.pop(next(iter(bodies)))
    bodies[key] = made
    return made


def _needs_package(name: str, what: str) -> None:
    if importlib.util.find_spec(name) is None:
        raise PleError(f"{what} needs the Python package {name!r}, which Blender's Python does not have "
                       "(install it into Blender's Python to use this)")


def _point(rig, obj, label: str) -> np.ndarray:
    if obj is None:
        raise PleError(f"Grade: choose {label}")
    return np.array(rig.matrix_world.inverted() @ obj.matrix_world.translation, dtype=float)


def radius_field(rig, settings, the_body=None):
    """The panel's graded thickness as a core radius field (None for none)."""
    if settings.grade == "LINEAR":
        a, b = _point(rig, settings.grade_a, "Empty A"), _point(rig, settings.grade_b, "Empty B")
        return grading.LinearGradient(a, b, settings.factor_a, settings.factor_b)
    if settings.grade == "SURFACE":
        if the_body is None:
            raise PleError("Grade Surface: choose a Body")
        return body.SurfaceDistanceField(the_body, settings.depth, settings.factor_a, settings.factor_b)
    return None


def active(rig) -> bool:
    s = rig.ple_body
    return s.body is not None or s.grade != "NONE"


def fill(rig, lat, region):
    """``lat`` graded, filtered by the body and cleaned up as the panel says (``lat`` itself when
    the panel is unused); the cleanup's report line is kept for the panel."""
    s = rig.ple_body
    if not active(rig):
        return lat
    the_body = body_of(rig, s) if s.body is not None else None
    field = radius_field(rig, s, the_body)
    out = lat
    if field is not None:
        out = lat.copy()
        out.set_radius_field(field)
    if the_body is not None:
        out = out.with_filter(body.BodyFilter(the_body, s.fill.lower()))
    if s.cleanup and region is not None:
        if the_body is None:
            raise PleError("Cleanup: choose a Body (cleanup removes what trimming to a body leaves)")
        out, report = cleanup.cleanup(out, region, skin=s.skin if s.skin > 0 and s.keep_skin else None)
        SESSION.cache("body reports")[rig.ple.uid] = str(report)
    else:
        SESSION.cache("body reports").pop(rig.ple.uid, None)
    return out


def signature(rig) -> tuple:
    """What the panel's result depends on: settings, the body's mesh and transform, the empties."""
    s = rig.ple_body
    if not active(rig):
        return ()
    parts = [s.fill, s.open_winding, s.skin, s.cleanup, s.keep_skin, s.grade, s.factor_a, s.factor_b, s.depth,
             tuple(rig.matrix_world.inverted().col[3])]
    if s.body is not None:
        verts, tris = mesh_arrays(s.body)
        parts += [s.body.name, hash(verts.tobytes()), hash(tris.tobytes()), relative(rig, s.body).round(9).tobytes()]
    for obj in (s.grade_a, s.grade_b):
        parts.append(None if obj is None else (obj.name, tuple(obj.matrix_world.translation)))
    return tuple(parts)


def users_of(obj) -> list:
    """Rigs whose panel uses ``obj`` (as body or gradient empty)."""
    return [r for r in bpy.data.objects if r.ple.role == "RIG"
            and obj in (r.ple_body.body, r.ple_body.grade_a, r.ple_body.grade_b)]


def rigs_in_updates(objects) -> list[str]:
    """Names of the rigs whose body or gradient empty moved or whose body mesh was edited (of the
    updated ``objects``; a ``watchers`` hook of the rig's depsgraph handler)."""
    seen = {}
    for obj in objects:
        if obj.ple.role != "NONE" or obj.type not in ("MESH", "EMPTY"):
            continue
        for r in users_of(obj):
            seen[r.name] = True
    return list(seen)


# ----- panel and operators --------------------------------------------------------------------------
class PLE_PT_body(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Body"

    def draw(self, context):
        rig = self.rig(context)
        s = rig.ple_body
        layout = self.layout
        layout.prop(s, "body")
        layout.prop(s, "fill")
        layout.prop(s, "open_winding")
        layout.prop(s, "skin")
        row = layout.row(align=True)
        row.prop(s, "cleanup")
        row.prop(s, "keep_skin")
        layout.prop(s, "grade")
        if s.grade == "LINEAR":
            layout.prop(s, "grade_a")
            layout.prop(s, "grade_b")
        if s.grade != "NONE":
            row = layout.row(align=True)
            row.prop(s, "factor_a")
            row.prop(s, "factor_b")
        if s.grade == "SURFACE":
            layout.prop(s, "depth")
        layout.operator("ple.skin_solid", icon="MOD_SOLIDIFY")
        report = SESSION.cache("body reports").get(rig.ple.uid)
        if report:
            layout.label(text=report)


class PLE_OT_body_fill(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Fill a mesh object with the lattice: keep what the fill mode says, optionally clean up and
    grade (for scripts: the Body panel sets the same settings)"""

    bl_idname = "ple.body_fill"
    bl_label = "Fill Body"
    bl_options = {"REGISTER", "UNDO"}

    rig: StringProperty(name="Rig", description="Lattice object (default: the active one)")
    body: StringProperty(name="Body", description="Mesh object to fill ('' clears the body)")
    fill: EnumProperty(name="Fill", items=FILL_MODES, default="INSIDE")
    skin: FloatProperty(name="Skin", min=0.0, default=0.0)
    cleanup: BoolProperty(name="Cleanup", default=False)
    keep_skin: BoolProperty(name="Keep beams on the skin", default=True)
    open_winding: BoolProperty(name="Open mesh: winding numbers", default=False)

    def execute(self, context):
        rig = model.rig_of(bpy.data.objects.get(self.rig) if self.rig else context.active_object)
        if rig is None:
            self.report({"ERROR"}, "select a PLE lattice object (or one of its frames)")
            return {"CANCELLED"}
        obj = bpy.data.objects.get(self.body) if self.body else None
        if self.body and (obj is None or obj.type != "MESH"):
            self.report({"ERROR"}, f"{self.body!r} is not a mesh object")
            return {"CANCELLED"}
        s = rig.ple_body
        old = {k: getattr(s, k) for k in ("body", "fill", "skin", "cleanup", "keep_skin", "open_winding")}
        new = {"body": obj, "fill": self.fill, "skin": self.skin, "cleanup": self.cleanup,
               "keep_skin": self.keep_skin, "open_winding": self.open_winding}
        events.set_quietly(s, **new)  # one redraw after, not one per setting
        err = sync.refresh(rig, force=True)
        if err:  # a bad body (open, empty, NaN) is refused: the previous settings come back
            events.set_quietly(s, **old)
            sync.refresh(rig, force=True)
            rig.ple.status = err
            self.report({"ERROR"}, err)
            return {"CANCELLED"}
        return {"FINISHED"}


class PLE_OT_skin_solid(bpy.types.Operator):  # noqa: N801 - Blender naming
    """Unite the body's skin (a shell of the panel's thickness) with the lattice filling the drawn
    region into one watertight mesh object (manifold3d Booleans)"""

    bl_idname = "ple.skin_solid"
    bl_label = "Skin Solid"
    bl_options = {"REGISTER", "UNDO"}

    rig: StringProperty(name="Rig", description="Lattice object (default: the active one)")

    def execute(self, context):
        rig = model.rig_of(bpy.data.objects.get(self.rig) if self.rig else context.active_object)
        if rig is None:
            self.report({"ERROR"}, "select a PLE lattice object (or one of its frames)")
            return {"CANCELLED"}
        try:
            s = rig.ple_body
            if s.body is None or s.skin <= 0:
                raise PleError("Skin Solid: choose a Body and a Skin thickness above 0")
            _needs_package("manifold3d", "a skin")
            lat = model.shown_lattice(rig)
            region = model.region_of(rig, lat)
            if region is None:
                raise PleError("the region is empty: set Region from/to inside the repetition counts")
            pipeline = needs("app.pipeline")  # the one mesh pipeline: as ple mesh --skin
            solid = pipeline.skin_solid(pipeline.MeshRequest(lat, region, "refined"), body_of(rig, s), s.skin)
        except PleError as exc:
            rig.ple.status = str(exc)
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        verts, faces = np.asarray(solid.vertices, float), np.asarray(solid.faces)
        # Blender keeps float32 coordinates: weld as the core's float32 writers do (vertices on one
        # grid point are one vertex), so merging by position cannot change the solid's topology
        verts, faces, _ = weld.weld(verts, faces, weld.grid_spacing(verts.min(axis=0), verts.max(axis=0)))
        me = draw.mesh_from_arrays(f"{rig.name}.skin", verts, faces)
        obj = bpy.data.objects.new(me.name, me)
        for coll in rig.users_collection:
            coll.objects.link(obj)
        obj.matrix_world = rig.matrix_world
        self.report({"INFO"}, f"{len(solid.faces)} triangles, volume {solid.volume:.6g}")
        return {"FINISHED"}


CLASSES = (PLE_BodySettings, PLE_PT_body, PLE_OT_body_fill, PLE_OT_skin_solid)


HOOKS = (("shown", fill), ("filtering", active), ("signatures", signature), ("watchers", rigs_in_updates))


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.ple_body = PointerProperty(type=PLE_BodySettings)
    for name, fn in HOOKS:
        hooks.add(name, fn)


def unregister():
    for name, fn in HOOKS:
        hooks.remove(name, fn)
    del bpy.types.Object.ple_body
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    SESSION.caches.pop("bodies", None)
    SESSION.caches.pop("body reports", None)
