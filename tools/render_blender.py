"""Render the add-on's rig for the docs: ``python -m tools.render_blender`` writes
``docs/img/addon_rig.png`` (Workbench, headless through EGL, in a subprocess); with ``--clg
--preset plate`` a CLG rig and its preview mesh (``docs/img/addon_clg_rig.png``).

The picture shows the default rig of the thesis Fig. 6.3 lattice exactly as the extension
makes it (no overrides): the cage (isocurves of the steady 3-map, bevelled, material
"PLE cage", orange) and the default 3x3x3 region (balls and cone-beams, "PLE region", blue),
in the Workbench engine with material colours (what the viewport shows).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from ple_addon import register
from ple_addon.rig import model

ROOT = Path(__file__).resolve().parent.parent


def render(out: Path, preset: str, region: tuple, size: tuple, clg: bool = False) -> None:
    """Runs inside the child process (bpy state is global)."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp())
    import bpy
    import numpy as np
    from mathutils import Vector

    bpy.ops.wm.read_factory_settings(use_empty=True)
    register()
    add = bpy.ops.ple.clg_add if clg else bpy.ops.ple.lattice_add  # a CLG rig: preview mesh over the region
    add(source="PRESET", preset=preset, region=region)
    r = bpy.context.active_object
    p = model.parts(r)
    bpy.context.view_layer.update()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = size
    shading = scene.display.shading
    shading.light, shading.color_type, shading.show_cavity = "STUDIO", "MATERIAL", True
    scene.world = bpy.data.worlds.new("w")
    pts = np.concatenate([np.array([tuple(q.co)[:3] for q in s.points]) for s in p["cage"].data.splines])
    centre, extent = pts.mean(axis=0), float(np.linalg.norm(pts.max(0) - pts.min(0)))
    cam_data = bpy.data.cameras.new("cam")
    cam = bpy.data.objects.new("cam", cam_data)
    scene.collection.objects.link(cam)
    direction = Vector((0.35, -1.0, 0.75)).normalized()
    cam.location = Vector(centre.tolist()) + direction * extent * 1.5
    cam.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = extent * 10
    scene.camera = cam
    scene.render.filepath = str(out)
    scene.render.image_settings.file_format = "PNG"
    bpy.ops.render.render(write_still=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "addon_rig.png"))
    ap.add_argument("--preset", default="fig6_3")
    ap.add_argument("--region", default="3,3,3", help="node-groups drawn in full per direction (the default rig's)")
    ap.add_argument("--size", default="960x600")
    ap.add_argument("--clg", action="store_true", help="PRESET is a CLG preset: render a CLG rig")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    if args.child:
        render(out, args.preset, tuple(int(x) for x in args.region.split(",")),
               tuple(int(x) for x in args.size.split("x")), args.clg)
        return 0
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "tools.render_blender", "--child", "--out", str(out), "--preset", args.preset,
           "--region", args.region, "--size", args.size] + (["--clg"] if args.clg else [])
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if res.returncode != 0 or not out.is_file():
        sys.stderr.write(res.stdout[-2000:] + res.stderr[-2000:])
        return 1
    _quantize(out)
    print(out)
    return 0


def _quantize(png: Path) -> None:
    """Palette-quantize the picture so the repository stays small (skipped without Pillow)."""
    try:
        from PIL import Image
    except ImportError:
        return
    with Image.open(png) as img:
        small = img.convert("RGB").quantize(colors=64)
    small.save(png, optimize=True)


if __name__ == "__main__":
    sys.exit(main())
