"""Headless batch export through Blender, on Dask: ``python -m ple_addon.batch --program P
--param thickness=0.05:0.1:5 … --style refined --format stl --out DIR [--scheduler local|sync|ADDRESS]``.

Runs with the project's Python (which has the ``bpy`` module). The variants and file names are
those of ``ple batch`` (``ple.app.batch.plan``). Each variant is one Dask task
(``ple.app.cluster``: an embedded local cluster by default, a running scheduler with
``--scheduler tcp://HOST:PORT``, or ``sync`` in this process) that runs with ``bpy`` imported in
the worker process. A worker installs the extension once, from its zip (sent to the workers with
the job, so they need no shared disk but the output folder); every task then starts from a clean
Blender state — an empty scene, or the ``--blend`` template opened afresh — builds the variant's
rig with ``ple.lattice_add``, sets the program inputs, tessellates the whole lattice with
``ple.tessellate`` and exports the new mesh object with Blender's exporter (STL, PLY, OBJ, GLB)
or the core's (3MF); ``--save-blend`` also saves each variant's scene (rig and mesh) as a
``.blend``. ``DIR/manifest.json`` records what was produced; finished outputs are skipped on a
re-run; a variant that fails is reported by name and the others go on. No geometry here: only
Blender plumbing.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from .corelink import PleError, core

ROOT = Path(__file__).resolve().parent.parent
STYLES = {"chocc": "CHOCC", "cnt": "CNT", "refined": "REFINED"}


# ----- client: plan, Dask, manifest ---------------------------------------------------------------
def build_zip(tmp: Path) -> Path:
    """The extension's zip built from this checkout into ``tmp`` by ``ple_addon/build.py``, run as
    a script: ``-m ple_addon.build`` would import the add-on (and bpy) first, a second for nothing."""
    proc = subprocess.run([sys.executable, str(ROOT / "ple_addon" / "build.py"), "--out", str(tmp)], cwd=ROOT,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"error: building the extension failed: {proc.stderr.strip()[-500:]}")
    return Path(proc.stdout.strip().splitlines()[-1])


def run(args) -> int:
    plan, prepare_output_dir = core("app.batch").plan, core("app.batch").prepare_output_dir
    dask_client, run_tasks = core("app.cluster").dask_client, core("app.cluster").run_tasks
    atomic_write_text = core("io.files").atomic_write_text
    try:
        if args.style not in STYLES:
            raise PleError(f"--style {args.style!r}: expected one of {', '.join(STYLES)}")
        if args.blend is not None and not Path(args.blend).is_file():
            raise PleError(f"--blend {args.blend}: no such file")
        source, variants = plan(args.program, args.param, args.format)
        out = Path(args.out)
        manifest_path = out / "manifest.json"
        manifest = prepare_output_dir(out, "python -m ple_addon.batch")
        done = {e["file"] for e in manifest["outputs"] if (out / e["file"]).is_file()}
        todo = [v for v in variants if v.filename not in done]
        manifest.update({"program": source, "style": args.style, "format": args.format, "engine": "blender",
                         "blend": None if args.blend is None else str(Path(args.blend).resolve())})
        manifest["outputs"] = [e for e in manifest["outputs"] if e["file"] in done]
        manifest["failures"] = []
        t0 = time.perf_counter()
        if todo:
            job = {"program": Path(source).read_text(), "style": args.style, "blend": manifest["blend"],
                   "save_blend": args.save_blend}
            with tempfile.TemporaryDirectory(prefix="ple-batch-") as tmp:
                workers = max(1, min(args.workers or os.cpu_count() or 1, len(todo)))
                start = contextlib.nullcontext() if args.scheduler == "sync" else _worker_start(Path(tmp))
                with start, dask_client(args.scheduler, workers) as client:
                    data = build_zip(Path(tmp)).read_bytes()
                    addon = (hashlib.sha256(data).hexdigest(), data)
                    if client is not None:  # a task, not scattered data: a worker's death cannot lose it
                        addon = client.submit(_held, addon, pure=False)  # the scheduler keeps it to run again
                    tasks = [(addon, job, v.params, str((out / v.filename).resolve())) for v in todo]
                    for v, result in run_tasks(client, blender_variant, tasks, todo, "blender batch",
                                               [v.filename for v in todo]):
                        if isinstance(result, Exception):
                            manifest["failures"].append({"file": v.filename, "params": v.params, "error": str(result)})
                        else:
                            manifest["outputs"].append(result)
                        atomic_write_text(manifest_path, json.dumps(manifest, indent=1) + "\n")
    except PleError as exc:
        print(f"ple_addon.batch: error: {exc}", file=sys.stderr)
        return 2
    atomic_write_text(manifest_path, json.dumps(manifest, indent=1) + "\n")
    summary = {"written": len(todo) - len(manifest["failures"]), "skipped": len(variants) - len(todo),
               "failed": manifest["failures"], "manifest": str(manifest_path),
               "seconds": round(time.perf_counter() - t0, 2)}
    for failure in manifest["failures"]:
        print(f"failed {failure['file']}: {failure['error']}", file=sys.stderr)
    print(json.dumps(summary, indent=1))
    return 2 if manifest["failures"] else 0


def _held(value):
    """``value`` itself, as a Dask task: the zip goes to each worker once (from the worker that ran
    this, as any task's result), and a worker killed with the only copy costs one rerun, whereas a
    scattered copy lost with its worker cancels every variant that needs it."""
    return value


@contextlib.contextmanager
def _worker_start(tmp: Path):
    """While the embedded cluster's workers start (from this process's path and environment):
    ``sys.path`` without the folders ``import bpy`` put before everything (Blender's own
    ``scripts/modules/bpy`` would shadow the ``bpy`` module there), and Blender's user resources
    in ``tmp`` unless the caller chose them (the extension's wheels are installed there, not into
    the user's Blender)."""
    import bpy

    blender = tuple(str(Path(bpy.utils.resource_path(kind))) for kind in ("LOCAL", "USER"))
    saved, env = list(sys.path), os.environ.get("BLENDER_USER_RESOURCES")
    sys.path[:] = [p for p in saved if not p.startswith(blender)]
    os.environ.setdefault("BLENDER_USER_RESOURCES", str(tmp))
    try:
        yield
    finally:
        sys.path[:] = saved
        if env is None:
            os.environ.pop("BLENDER_USER_RESOURCES")


# ----- worker: bpy in the worker process ------------------------------------------------------------
_BLENDER: dict = {}  # zip hash -> (bpy, the installed extension's package): installed once per process
# Blender runs on the thread that imported bpy (the package ``ple_addon`` imports it just before
# this module): the main thread when this module was an embedded worker's main module (its
# ``__mp_main__``, run first) or a worker's ``--preload``; a Dask worker that first met it while
# unpickling a task, on another thread, cannot run it
BPY_ON_MAIN_THREAD = (threading.current_thread() is threading.main_thread()
                      or getattr(getattr(sys.modules.get("__mp_main__"), "__spec__", None), "name", None) == __name__)


def _blender(addon: tuple[str, bytes]):
    """``bpy`` in this process with the extension of ``addon`` (hash, zip bytes) installed and
    enabled, once per process, into an extension repository of this process's own (a temporary
    folder, never saved in the preferences): workers on one machine never install into each
    other's folder nor into the user's Blender."""
    sha, data = addon
    if sha in _BLENDER:
        return _BLENDER[sha]
    import importlib

    import addon_utils
    import bpy

    folder = Path(tempfile.mkdtemp(prefix="ple-blender-worker-"))
    atexit.register(shutil.rmtree, folder, True)
    (folder / "ple.zip").write_bytes(data)
    module = f"ple_batch_{sha[:12]}"
    bpy.context.preferences.extensions.repos.new(name=module, module=module, custom_directory=str(folder / "repo"),
                                                 source="USER")
    # one install at a time on a machine: the extension's wheels go to the (shared) user resources
    with open(Path(tempfile.gettempdir()) / f"ple-blender-install-{sha[:12]}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        bpy.ops.extensions.package_install_files(filepath=str(folder / "ple.zip"), repo=module,
                                                 enable_on_install=True)
    name = f"bl_ext.{module}.ple"
    addon_utils.enable(name, default_set=True)
    _BLENDER[sha] = (bpy, importlib.import_module(name))
    return _BLENDER[sha]


def blender_variant(addon, job: dict, params: dict, path: str) -> dict:
    """One variant, as a Dask task: a clean Blender state (an empty scene, or the template .blend
    opened afresh), the variant's rig, its mesh, the export. Returns its manifest entry; a failure
    is raised as a PleError naming its cause (reported by name, the other variants go on).

    Blender's API works only on the process's main thread (elsewhere its operators crash), and a
    Dask task runs on a worker thread: the task hands its work to the worker's main thread (its
    event loop) and waits, so one variant at a time runs with ``bpy`` in each worker process."""
    if threading.current_thread() is threading.main_thread():
        return _variant_here(addon, job, params, path)
    if not BPY_ON_MAIN_THREAD:
        raise PleError("this Dask worker imported bpy outside its main thread, where Blender cannot run: start "
                       "it with `dask worker ADDRESS --nthreads 1 --preload ple_addon.batch`")
    from distributed import get_worker
    from distributed.utils import sync

    async def on_main_thread():
        return _variant_here(addon, job, params, path)

    return sync(get_worker().loop, on_main_thread)


def _variant_here(addon, job: dict, params: dict, path: str) -> dict:
    t0 = time.perf_counter()
    bpy, ext = _blender(addon)
    try:
        if job["blend"]:
            bpy.ops.wm.open_mainfile(filepath=job["blend"], load_ui=False)
        else:
            bpy.ops.wm.read_homefile(use_empty=True, load_ui=False)
        entry = _one_variant(bpy, ext, job, params, Path(path))
    except Exception as exc:  # the program, the rig or the exporter refused this variant
        raise PleError(f"{type(exc).__name__}: {exc}") from None
    return {"file": Path(path).name, "params": params, **entry, "seconds": round(time.perf_counter() - t0, 3),
            "worker_pid": os.getpid()}


def _one_variant(bpy, ext, job: dict, params: dict, path: Path) -> dict:
    """One variant in this Blender, through the installed extension ``ext`` (its rig, and its core
    through its ``corelink``)."""
    import numpy as np

    model, sync = ext.rig.model, ext.rig.sync

    objects_before = len(bpy.data.objects)
    text = bpy.data.texts.new("program.py")
    text.from_string(job["program"])
    if bpy.ops.ple.lattice_add(source="TEXT", text=text.name, region=(1, 1, 1)) != {"FINISHED"}:
        raise RuntimeError("ple.lattice_add failed (see the program)")
    rig = bpy.context.view_layer.objects.active
    for name, value in params.items():
        rig[model.PARAM_PREFIX + name] = value
    sync.refresh(rig, force=True)
    if rig.ple.status:
        raise RuntimeError(rig.ple.status)
    rig.ple.region_min = (0, 0, 0)
    rig.ple.region_max = tuple(model.lattice_of(rig).counts)
    sync.refresh(rig, force=True)
    meshes_before = set(bpy.data.objects)
    if bpy.ops.ple.tessellate(style=STYLES[job["style"]]) != {"FINISHED"}:
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
        mesh = trimesh.Trimesh(verts.reshape(-1, 3), faces.reshape(-1, 3), process=False)
        ext.corelink.core("io.export").export_mesh(mesh, tmp)
    os.replace(tmp, path)
    entry = {"triangles": sum(len(p.vertices) - 2 for p in obj.data.polygons), "bytes": path.stat().st_size,
             "objects_at_start": objects_before}
    if job["save_blend"]:  # the variant's scene: its rig (program, inputs) and its mesh
        blend = path.with_suffix(".blend")
        tmp = blend.with_name(f".{blend.name}.part.blend")
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True, compress=True)
        os.replace(tmp, blend)
        entry["blend"] = blend.name
    return entry


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ple_addon.batch", description=__doc__.split("\n\n")[0])
    ap.add_argument("--program", required=True, help="a program .py or a preset name")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=SWEEP",
                    help="value, v1,v2,… or lo:hi:n (repeatable; variants are the Cartesian product)")
    ap.add_argument("--style", default="refined", help="chocc, cnt or refined")
    ap.add_argument("--format", default="stl", choices=["stl", "3mf", "ply", "obj", "glb"])
    ap.add_argument("--blend", help="a template .blend (read by the workers): each task opens it afresh and "
                    "adds the variant's rig to it (default: an empty scene)")
    ap.add_argument("--save-blend", action="store_true", help="also save each variant's scene as <file>.blend")
    ap.add_argument("--scheduler", default="local", metavar="S",
                    help="local (an embedded Dask cluster, default), sync (this process) or a Dask scheduler "
                         "address tcp://HOST:PORT whose workers can import bpy and ple_addon")
    ap.add_argument("--workers", type=int, help="workers of the embedded cluster (default: all cores)")
    ap.add_argument("--out", required=True, help="output folder (manifest.json is written there)")
    return run(ap.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
