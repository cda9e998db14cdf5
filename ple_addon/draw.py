"""Every writer of Blender data from core arrays: the region mesh, the cage curve, frame matrices,
meshes of faces (tessellations, previews, solids), materials and the balls-and-beams modifier.

Bulk data goes through ``foreach_set`` on float32/int32 arrays; datablocks are reused (resized
only when the element counts change), so thousands of edits create no new datablocks.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

RADIUS_ATTR = "ple_radius"
NODE_GROUP = "PLE balls and beams"


def set_matrix(obj, m) -> tuple:
    """Set an object's local matrix if it differs; returns the stored (float32) values."""
    new = Matrix(np.asarray(m, dtype=float).tolist())
    cur = obj.matrix_basis
    if max(abs(a - b) for ra, rb in zip(cur, new) for a, b in zip(ra, rb)) > 1e-7:
        obj.matrix_basis = new
    return tuple(float(x) for row in obj.matrix_basis for x in row)


def new_region_mesh(name: str):
    return bpy.data.meshes.new(name)


def region_mesh(me, ev) -> None:
    """Vertices at ball centres, one edge per beam, ball radii as the point attribute
    ``ple_radius`` (the geometry-nodes modifier draws balls and cone-beams from them)."""
    n = 0 if ev is None else len(ev.center)
    m = 0 if ev is None else len(ev.beam_nodes)
    if len(me.vertices) != n or len(me.edges) != m:
        me.clear_geometry()
        me.vertices.add(n)
        me.edges.add(m)
    if n:
        me.attributes["position"].data.foreach_set("vector", ev.center.astype(np.float32).ravel())
        attr = me.attributes.get(RADIUS_ATTR) or me.attributes.new(RADIUS_ATTR, "FLOAT", "POINT")
        attr.data.foreach_set("value", ev.radius.astype(np.float32))
    if m:
        me.attributes[".edge_verts"].data.foreach_set("value", ev.beam_nodes.astype(np.int32).ravel())
    me.update()


def new_cage_curve(name: str, lat=None):
    """The cage's curve, bevelled to a third of the smallest ball radius (a curve without
    bevel never renders)."""
    cu = bpy.data.curves.new(name, "CURVE")
    cu.dimensions = "3D"
    radius = float(lat.template_radii.min()) if lat is not None and len(lat.nodes) else 0.05
    cu.bevel_depth = max(radius / 3.0, 1e-4)
    cu.bevel_resolution = 1
    return cu


# name, base colour (linear RGBA): the cage orange, the region blue, distinct in any render
CAGE_MATERIAL = ("PLE cage", (0.9, 0.35, 0.05, 1.0))
REGION_MATERIAL = ("PLE region", (0.1, 0.3, 0.9, 1.0))


def material(spec):
    """A shared material (created once): Principled BSDF base colour and viewport colour."""
    name, color = spec
    mat = bpy.data.materials.get(name)
    if mat is None:
        mat = bpy.data.materials.new(name)
        mat.diffuse_color = color
        mat.use_nodes = True
        bsdf = mat.node_tree.nodes.get("Principled BSDF")
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = color
            bsdf.inputs["Roughness"].default_value = 0.4
    return mat


def set_material(obj, spec) -> None:
    """Give the object's data the material; for the region also the balls-and-beams modifier's
    Material input (geometry made by nodes carries no material of its own)."""
    mat = material(spec)
    if obj.data is not None and mat.name not in obj.data.materials:
        obj.data.materials.append(mat)
    mod = obj.modifiers.get("PLE balls and beams")
    if mod is not None and mod.node_group is not None:
        for item in mod.node_group.interface.items_tree:
            if getattr(item, "in_out", None) == "INPUT" and item.name == "Material":
                mod[item.identifier] = mat


def cage_curve(cu, curves) -> None:
    """One poly spline per isocurve (arrays (s, 3)); reuses the splines if their sizes match."""
    sizes = [len(c) for c in curves]
    if [len(s.points) for s in cu.splines] != sizes:
        cu.splines.clear()
        for size in sizes:
            sp = cu.splines.new("POLY")
            sp.points.add(size - 1)
    for sp, c in zip(cu.splines, curves):
        co = np.ones((len(c), 4), dtype=np.float32)
        co[:, :3] = c
        sp.points.foreach_set("co", co.ravel())
    cu.update_tag()


def balls_beams_group():
    """The shared geometry-nodes group: an icosphere instance per vertex scaled by its radius,
    a circle swept along every edge scaled by the radii of its ends (a cone-beam preview)."""
    ng = bpy.data.node_groups.get(NODE_GROUP)
    if ng is not None:
        return ng
    ng = bpy.data.node_groups.new(NODE_GROUP, "GeometryNodeTree")
    ng.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    detail = ng.interface.new_socket("Ball detail", in_out="INPUT", socket_type="NodeSocketInt")
    detail.default_value, detail.min_value, detail.max_value = 1, 0, 4
    sides = ng.interface.new_socket("Beam sides", in_out="INPUT", socket_type="NodeSocketInt")
    sides.default_value, sides.min_value, sides.max_value = 8, 3, 64
    ng.interface.new_socket("Material", in_out="INPUT", socket_type="NodeSocketMaterial")
    ng.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = ng.nodes, ng.links
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    radius = nodes.new("GeometryNodeInputNamedAttribute")
    radius.data_type = "FLOAT"
    radius.inputs["Name"].default_value = RADIUS_ATTR
    points = nodes.new("GeometryNodeMeshToPoints")
    sphere = nodes.new("GeometryNodeMeshIcoSphere")
    sphere.inputs["Radius"].default_value = 1.0
    balls = nodes.new("GeometryNodeInstanceOnPoints")
    curve = nodes.new("GeometryNodeMeshToCurve")
    circle = nodes.new("GeometryNodeCurvePrimitiveCircle")
    circle.inputs["Radius"].default_value = 1.0
    beams = nodes.new("GeometryNodeCurveToMesh")
    join = nodes.new("GeometryNodeJoinGeometry")
    links.new(gin.outputs["Ball detail"], sphere.inputs["Subdivisions"])
    links.new(gin.outputs["Beam sides"], circle.inputs["Resolution"])
    links.new(gin.outputs[0], points.inputs["Mesh"])
    links.new(points.outputs["Points"], balls.inputs["Points"])
    links.new(sphere.outputs["Mesh"], balls.inputs["Instance"])
    links.new(radius.outputs["Attribute"], balls.inputs["Scale"])
    links.new(gin.outputs[0], curve.inputs["Mesh"])
    links.new(curve.outputs["Curve"], beams.inputs["Curve"])
    links.new(circle.outputs["Curve"], beams.inputs["Profile Curve"])
    links.new(radius.outputs["Attribute"], beams.inputs["Scale"])
    links.new(balls.outputs["Instances"], join.inputs["Geometry"])
    links.new(beams.outputs["Mesh"], join.inputs["Geometry"])
    set_mat = nodes.new("GeometryNodeSetMaterial")
    links.new(join.outputs["Geometry"], set_mat.inputs["Geometry"])
    links.new(gin.outputs["Material"], set_mat.inputs["Material"])
    links.new(set_mat.outputs["Geometry"], gout.inputs[0])
    return ng


def add_balls_beams_modifier(obj) -> None:
    mod = obj.modifiers.new("PLE balls and beams", "NODES")
    mod.node_group = balls_beams_group()


# (elements drawn, ball detail, beam sides): coarser drawing for big regions keeps edits interactive
DETAIL_LEVELS = ((8_000, 1, 8), (30_000, 0, 6), (None, 0, 4))


def set_detail(obj, elements: int) -> None:
    """Pick the drawing detail of the balls-and-beams modifier from the number of elements."""
    mod = obj.modifiers.get("PLE balls and beams")
    if mod is None or mod.node_group is None:
        return
    _, detail, sides = next(level for level in DETAIL_LEVELS if level[0] is None or elements <= level[0])
    ids = {item.name: item.identifier for item in mod.node_group.interface.items_tree
           if getattr(item, "in_out", None) == "INPUT"}
    for name, value in (("Ball detail", detail), ("Beam sides", sides)):
        key = ids.get(name)
        if key is not None and mod.get(key) != value:
            mod[key] = value


def mesh_from_arrays(name: str, verts, faces, me=None):
    """A mesh of vertices (n, 3) and faces (f, k) of k corners each (a new one, or ``me`` refilled)."""
    if me is None:
        me = bpy.data.meshes.new(name)
    else:
        me.clear_geometry()
    if not len(verts):  # nothing (an empty region): an empty mesh has no attribute arrays to fill
        me.update()
        return me
    k = faces.shape[1] if len(faces) else 3
    me.vertices.add(len(verts))
    me.loops.add(k * len(faces))
    me.polygons.add(len(faces))
    # views, not copies, of float32 / int32 C-contiguous arrays (a Tessellate's mapped files)
    me.attributes["position"].data.foreach_set("vector", np.ascontiguousarray(verts, np.float32).reshape(-1))
    me.attributes[".corner_vert"].data.foreach_set("value", np.ascontiguousarray(faces, np.int32).reshape(-1))
    me.polygons.foreach_set("loop_start", np.arange(0, k * len(faces), k, dtype=np.int32))
    me.update(calc_edges=True)
    return me


def register() -> None:
    pass


def unregister() -> None:
    pass
