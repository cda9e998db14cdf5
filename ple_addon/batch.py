"""Headless batch export through Blender: ``python -m ple_addon.batch --program P
--param thickness=0.05:0.1:5 … --style refined --format stl --out DIR``.

Runs with the project's Python (which has the ``bpy`` module). The variants and file names
are those of ``ple batch`` (``ple.batch.plan``); the work is split over worker processes
(one per core), each a background Blender that installs the extension from its zip, builds
each variant's rig with ``ple.lattice_add``, sets the program inputs, tessellates the whole
lattice with ``ple.tessellate`` and exports the new mesh object with Blender's exporter
(STL, PLY, OBJ, GLB) or the core's (3MF). ``DIR/manifest.json`` records what was produced;
finished outputs are skipped on a re-run. No geometry here: only Blender plumbing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STYLES = {"chocc": "CHOCC", "cnt": "CNT", "refined": "REFINED"}


# ----- parent process: plan, workers, manifest ---------------------------------------------------
def build_zip(tmp: Path) -> Path:
    proc = subprocess.run([sys.executable, "-m", "ple_addon.build", "--out", str(tmp)], cwd=ROOT,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"error: building the extension failed: {proc.stderr.strip()[-500:]}")
    return Path(proc.stdout.strip().splitlines()[-1])


def run(args) -> int:
    from ple.app.batch import plan, prepare_output_dir
    from ple.app.progress import Progress
    from ple.errors import PleError
    from ple.io.files import atomic_write_text

    try:
        if args.style not in STYLES:
            raise PleError(f"--style {args.style!r}: expected one of {', '.join(STYLES)}")
        source, variants = plan(args.program, args.param, args.format)
        out = Path(args.out)
        manifest_path = out / "manifest.json"
        manifest = prepare_output_dir(out, "python -m ple_addon.batch")
    except PleError as exc:
        print(f"ple_addon.batch: error: {exc}", file=sys.stderr)
        return 2
    done = {e["file"] for e in manifest["outputs"] if (out / e["file"]).is_file()}
    todo = [v for v in variants if v.filename not in done]
    manifest.update({"program": source, "style": args.style, "format": args.format, "engine": "blender"})
    manifest["outputs"] = [e for e in manifest["outputs"] if e["file"] in done]
    manifest["failures"] = []
    jobs = max(1, min(args.jobs or os.cpu_count() or 1, len(todo) or 1))
    t0 = time.perf_counter()
    if todo:
        with tempfile.TemporaryDirectory(prefix="ple-batch-") as tmp:
            zip_path = build_zip(Path(tmp))
            workers = []
            for w in range(jobs):
                share = [{"params": v.params, "file": str(out / v.filename)} for v in todo[w::jobs]]
                job = Path(tmp) / f"job{w}.json"
                job.write_text(json.dumps({"zip": str(zip_path), "program": source, "style": args.style,
                                           "variants": share}))
                env = dict(os.environ, BLENDER_USER_RESOURCES=str(Path(tmp) / f"user{w}"))
                workers.append(subprocess.Popen([sys.executable, "-m", "ple_addon.batch", "--worker", str(job)],
                                                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                                text=True, env=env))
            bar = Progress(len(todo), "batch")
            for proc in workers:
                for line in proc.stdout:
                    if not line.startswith("PLE-RESULT "):
                        continue
                    entry = json.loads(line[len("PLE-RESULT "):])
                    (manifest["failures"] if "error" in entry else manifest["outputs"]).append(entry)
                    atomic_write_text(manifest_path, json.dumps(manifest, indent=1) + "\n")
                    bar.update(1, entry.get("file", ""))
                err = proc.stderr.read()
                if proc.wait() != 0:
                    print(f"ple_addon.batch: a Blender worker failed: {err.strip()[-800:]}", file=sys.stderr)
                    return 1
    atomic_write_text(manifest_path, json.dumps(manifest, indent=1) + "\n")
    summary = {"written": len(todo) - len(manifest["failures"]), "skipped": len(variants) - len(todo),
               "failed": manifest["failures"], "manifest": str(manifest_path),
               "seconds": round(time.perf_counter() - t0, 2)}
    print(json.dumps(summary, indent=1))
    return 2 if manifest["failures"] else 0


# ----- worker process: background Blender ---------------------------------------------------------
def worker(job_path: str) -> int:
    job = json.loads(Path(job_path).read_text())
    import addon_utils
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.extensions.package_install_files(filepath=job["zip"], repo="user_default", enable_on_install=True)
    addon_utils.enable("bl_ext.user_default.ple", default_set=True)
    import importlib
    rigmod = importlib.import_module("bl_ext.user_default.ple.rig")
    core_export = importlib.import_module("bl_ext.user_default.ple.vendor.ple.io.export")
    source = Path(job["program"]).read_text()
    for item in job["variants"]:
        t0 = time.perf_counter()
        entry = {"file": Path(item["file"]).name, "params": item["params"]}
        try:
            entry.update(_one_variant(bpy, rigmod, core_export, source, item["params"], job["style"],
                                      Path(item["file"])))
            entry["seconds"] = round(time.perf_counter() - t0, 3)
        except Exception as exc:  # a variant the program or the exporter rejects: reported, others go on
            entry["error"] = f"{type(exc).__name__}: {exc}"
        print("PLE-RESULT " + json.dumps(entry), flush=True)
    return 0


def _one_variant(bpy, rigmod, core_export, source: str, params: dict, style: str, path: Path) -> dict:
    import numpy as np

    text = bpy.data.texts.new("program.py")
    text.from_string(source)
    before = set(bpy.data.objects)
    result = bpy.ops.ple.lattice_add(source="TEXT", text=text.name, region=(1, 1, 1))
    if result != {"FINISHED"}:
        raise RuntimeError("ple.lattice_add failed (see the program)")
    rig = bpy.context.view_layer.objects.active
    for name, value in params.items():
        rig[rigmod.PARAM_PREFIX + name] = value
    rigmod.refresh(rig, force=True)
    if rig.ple.status:
        raise RuntimeError(rig.ple.status)
    rig.ple.region_min = (0, 0, 0)
    rig.ple.region_max = tuple(rigmod.lattice_of(rig).counts)
    rigmod.refresh(rig, force=True)
    meshes_before = set(bpy.data.objects)
    if bpy.ops.ple.tessellate(style=STYLES[style]) != {"FINISHED"}:
        raise RuntimeError(f"ple.tessellate failed: {rig.ple.status}")
    (obj,) = [o for o in bpy.data.objects if o not in meshes_before and o.type == "MESH"]
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    tmp = path.with_name(f".{path.name}.part{path.suffix}")
    fmt = path.suffix[1:].lower()
    if fmt == "stl":
        bpy.ops.wm.stl_export(filepath=str(tmp), export_selected_objects=True, ascii_format=False)
    elif fmt == "ply":
        bpy.ops.wm.ply_export(filepath=str(tmp), export_selected_objects=True, export_normals=False,
                              export_uv=False, export_colors="NONE")
    elif fmt == "obj":
        bpy.ops.wm.obj_export(filepath=str(tmp), export_selected_objects=True, export_materials=False,
                              export_uv=False, export_normals=False)
    elif fmt == "glb":
        bpy.ops.export_scene.gltf(filepath=str(tmp), export_format="GLB", use_selection=True)
    else:  # 3MF: Blender has no exporter; the core's writes the mesh data taken from Blender
        import trimesh
        me = obj.data
        verts = np.empty(len(me.vertices) * 3, np.float32)
        me.vertices.foreach_get("co", verts)
        faces = np.empty(len(me.polygons) * 3, np.int32)
        me.polygons.foreach_get("vertices", faces)
        core_export.export_mesh(trimesh.Trimesh(verts.reshape(-1, 3), faces.reshape(-1, 3), process=False), tmp)
    os.replace(tmp, path)
    triangles = sum(len(p.vertices) - 2 for p in obj.data.polygons)
    created = [o for o in bpy.data.objects if o not in before]
    data = [o.data for o in created if o.data is not None]
    bpy.data.batch_remove(created + data + [text])
    return {"triangles": triangles, "bytes": path.stat().st_size}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker(argv[1])
    ap = argparse.ArgumentParser(prog="python -m ple_addon.batch", description=__doc__.split("\n\n")[0])
    ap.add_argument("--program", required=True, help="a program .py or a preset name")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=SWEEP",
                    help="value, v1,v2,… or lo:hi:n (repeatable; variants are the Cartesian product)")
    ap.add_argument("--style", default="refined", help="chocc, cnt or refined")
    ap.add_argument("--format", default="stl", choices=["stl", "3mf", "ply", "obj", "glb"])
    ap.add_argument("--jobs", type=int, help="Blender worker processes (default: all cores)")
    ap.add_argument("--out", required=True, help="output folder (manifest.json is written there)")
    return run(ap.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
