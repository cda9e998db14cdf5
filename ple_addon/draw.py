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
        me.attributes[".edge_verts"].data.foreach_set("value", ev.beam_nodes.astype(np.int32, copy=False).ravel())
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


TAPERS = 9  # beam instances: cones whose far radius is 0, 1/8, …, 1 of the near one (the taper rounded)


def balls_beams_group():
    """The shared geometry-nodes group drawing a region as GPU instances: one icosphere per
    vertex scaled by its radius, one unit cone per edge (at its midpoint, turned along it,
    scaled by the larger end radius and the length; its taper picked among ``TAPERS`` cones).
    Nothing is swept or realized: an edit of the centres costs fields on the points and edges."""
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

    def node(kind, *inputs, **props):
        n = nodes.new(kind)
        for key, value in props.items():
            setattr(n, key, value)
        for socket, value in zip(n.inputs, inputs):
            if value is None:
                continue
            if hasattr(value, "is_output"):
                links.new(value, socket)
            else:
                socket.default_value = value
        return n

    def math(op, a, b=None):
        return node("ShaderNodeMath", a, b, operation=op).outputs[0]

    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    mesh = gin.outputs[0]
    radius = node("GeometryNodeInputNamedAttribute", data_type="FLOAT")
    radius.inputs["Name"].default_value = RADIUS_ATTR
    radius = radius.outputs["Attribute"]
    # balls: an icosphere on every vertex
    sphere = node("GeometryNodeMeshIcoSphere", 1.0, gin.outputs["Ball detail"])
    sphere = node("GeometryNodeSetMaterial", sphere.outputs["Mesh"], None, gin.outputs["Material"])
    points = node("GeometryNodeMeshToPoints", mesh)
    balls = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(points.outputs[0], balls.inputs["Points"])
    links.new(sphere.outputs[0], balls.inputs["Instance"])
    links.new(radius, balls.inputs["Scale"])
    # beams: per edge its ends, the larger radius first (the cone's base)
    ends = nodes.new("GeometryNodeInputMeshEdgeVertices")
    r1 = node("GeometryNodeSampleIndex", mesh, radius, ends.outputs["Vertex Index 1"], data_type="FLOAT",
              domain="POINT").outputs[0]
    r2 = node("GeometryNodeSampleIndex", mesh, radius, ends.outputs["Vertex Index 2"], data_type="FLOAT",
              domain="POINT").outputs[0]
    first = node("FunctionNodeCompare", r1, r2, operation="GREATER_EQUAL", data_type="FLOAT").outputs[0]
    along = node("ShaderNodeVectorMath", ends.outputs["Position 2"], ends.outputs["Position 1"],
                 operation="SUBTRACT").outputs[0]
    back = node("ShaderNodeVectorMath", along, None, None, -1.0, operation="SCALE").outputs[0]
    way = node("GeometryNodeSwitch", first, back, along, input_type="VECTOR").outputs[0]
    big, small = math("MAXIMUM", r1, r2), math("MINIMUM", r1, r2)
    length = node("ShaderNodeVectorMath", along, operation="LENGTH").outputs["Value"]
    taper = math("ROUND", math("MULTIPLY", math("DIVIDE", small, big), TAPERS - 1))
    turn = node("FunctionNodeAlignRotationToVector", None, 1.0, way, axis="Z").outputs[0]
    scale = node("ShaderNodeCombineXYZ", big, big, length).outputs[0]
    cap = node("GeometryNodeCaptureAttribute", mesh, domain="EDGE")
    captured = []
    for kind, name, value in (("ROTATION", "turn", turn), ("VECTOR", "scale", scale), ("FLOAT", "taper", taper)):
        cap.capture_items.new(kind, name)
        links.new(value, cap.inputs[name])
        captured.append(cap.outputs[name])
    bare = node("GeometryNodeRemoveAttribute", cap.outputs["Geometry"])  # not carried into 3 instances a ball
    bare.inputs["Name"].default_value = RADIUS_ATTR
    mids = node("GeometryNodeMeshToPoints", bare.outputs[0], mode="EDGES")
    cones = nodes.new("GeometryNodeGeometryToInstance")
    for k in reversed(range(TAPERS)):  # a multi-input socket lists its last link first
        cone = node("GeometryNodeMeshCone", gin.outputs["Beam sides"], 1, 1, k / (TAPERS - 1), 1.0, 1.0,
                    fill_type="NONE")
        cone = node("GeometryNodeTransform", cone.outputs["Mesh"])  # the primitive stands on z = 0
        cone.inputs["Translation"].default_value = (0.0, 0.0, -0.5)
        cone = node("GeometryNodeSetMaterial", cone.outputs[0], None, gin.outputs["Material"])
        links.new(cone.outputs[0], cones.inputs[0])
    beams = nodes.new("GeometryNodeInstanceOnPoints")
    links.new(mids.outputs[0], beams.inputs["Points"])
    links.new(cones.outputs[0], beams.inputs["Instance"])
    beams.inputs["Pick Instance"].default_value = True
    links.new(captured[2], beams.inputs["Instance Index"])
    links.new(captured[0], beams.inputs["Rotation"])
    links.new(captured[1], beams.inputs["Scale"])
    both = nodes.new("GeometryNodeGeometryToInstance")  # nested, not joined: a join copies every instance
    links.new(beams.outputs["Instances"], both.inputs[0])
    links.new(balls.outputs["Instances"], both.inputs[0])
    links.new(both.outputs[0], gout.inputs[0])
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
