"""Render meshes to PNG with Blender's Workbench engine, headless (run with the .venv python).

Usage: python tools/render_mesh.py OUT.png MESH.ply [MESH2.ply …] [--size 640x480] [--color r,g,b]
         [--curves CURVES.npz] [--view iso|top|front]
Each PLY is drawn as a solid object; CURVES.npz (array ``lines`` (L, P, 3)) as thin tubes, for cages.
This file only turns core results (written as files) into a picture: no geometry here.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="ple-bl-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402

PALETTE = [(0.85, 0.55, 0.25), (0.3, 0.55, 0.85), (0.45, 0.75, 0.4), (0.8, 0.35, 0.45)]


def _read_ply(path: str):
    import trimesh
    m = trimesh.load(path, process=False)
    return np.asarray(m.vertices, dtype=np.float32), np.asarray(m.faces, dtype=np.int32)


def _add_mesh(name: str, verts: np.ndarray, faces: np.ndarray, color) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.ravel())
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.color = (*color, 1.0)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _add_curves(lines: np.ndarray, width: float) -> bpy.types.Object:
    cu = bpy.data.curves.new("cage", "CURVE")
    cu.dimensions = "3D"
    cu.bevel_depth = width
    for line in lines:
        sp = cu.splines.new("POLY")
        sp.points.add(len(line) - 1)
        sp.points.foreach_set("co", np.c_[line, np.ones(len(line))].astype(np.float32).ravel())
    obj = bpy.data.objects.new("cage", cu)
    obj.color = (0.15, 0.15, 0.2, 1.0)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("meshes", nargs="*")
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--curves")
    ap.add_argument("--view", default="iso", choices=["iso", "top", "front"])
    args = ap.parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    pts = []
    for n, path in enumerate(args.meshes):
        v, f = _read_ply(path)
        _add_mesh(f"m{n}", v, f, PALETTE[n % len(PALETTE)])
        pts.append(v)
    if args.curves:
        lines = np.load(args.curves)["lines"]
        pts.append(lines.reshape(-1, 3))
    allp = np.concatenate(pts)
    lo, hi = allp.min(0), allp.max(0)
    centre, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo))
    if args.curves:
        _add_curves(lines, size * 0.0015)
    w, h = (int(x) for x in args.size.split("x"))
    scene.render.resolution_x, scene.render.resolution_y = w, h
    scene.render.engine = "BLENDER_WORKBENCH"
    shading = scene.display.shading
    shading.light = "STUDIO"
    shading.color_type = "OBJECT"
    shading.show_cavity = True
    shading.show_shadows = False
    scene.render.film_transparent = False
    world = bpy.data.worlds.new("w")
    scene.world = world
    direction = {"iso": Vector((1.0, -1.3, 0.9)), "top": Vector((0.01, -0.01, 1.0)),
                 "front": Vector((0.0, -1.0, 0.15))}[args.view].normalized()
    cam_data = bpy.data.cameras.new("cam")
    cam_data.lens = 50
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    cam.location = Vector(centre.tolist()) + direction * size * 1.5
    cam.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = size * 10
    scene.camera = cam
    # frame all points: widen the distance until every point projects inside the view
    from bpy_extras.object_utils import world_to_camera_view
    for _ in range(30):
        bpy.context.view_layer.update()
        sample = allp[:: max(1, len(allp) // 4000)]
        inside = all(0.03 < c.x < 0.97 and 0.03 < c.y < 0.97 and c.z > 0
                     for c in (world_to_camera_view(scene, cam, Vector(p.tolist())) for p in sample))
        if inside:
            break
        cam.location = Vector(centre.tolist()) + direction * (cam.location - Vector(centre.tolist())).length * 1.12
    scene.render.filepath = os.path.abspath(args.out)
    scene.render.image_settings.file_format = "PNG"
    bpy.ops.render.render(write_still=True)
    return 0 if math.isfinite(size) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
