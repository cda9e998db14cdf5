"""python -m ple_addon.batch: variants exported by Blender in Dask worker processes (``bpy``
imported there, a clean Blender state per task) match the core's meshes; on the embedded cluster,
on a real scheduler with a worker process, and in one process with a template .blend."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh
from daskcluster import dask_cluster
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

ROOT = Path(__file__).resolve().parents[2]


def run_batch(out: Path, tmp: Path, *extra: str, sweep: str = "radius=0.1,0.2,0.3") -> subprocess.CompletedProcess:
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp / "blender-user"))
    return subprocess.run([sys.executable, "-m", "ple_addon.batch", "--program", "cubic", "--param", "n=2",
                           "--param", sweep, "--style", "cnt", "--out", str(out), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=900, env=env)


def check_outputs(out: Path, count: int, objects_at_start: int = 0) -> list:
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["engine"] == "blender"
    assert len(manifest["outputs"]) == count
    for entry in manifest["outputs"]:
        mesh = trimesh.load(out / entry["file"])
        truth = tessellate(load_lattice("cubic", {"n": 2, "radius": entry["params"]["radius"]}), style="cnt")
        assert mesh.is_watertight
        assert len(mesh.faces) == len(truth.faces) == entry["triangles"]
        assert abs(mesh.volume - truth.volume) <= 1e-5 * truth.volume
        assert entry["objects_at_start"] == objects_at_start  # each task began from a clean Blender state
    return manifest["outputs"]


def test_embedded_cluster_exports_the_core_meshes_reports_failures_and_resumes(tmp_path):
    out = tmp_path / "out"
    res = run_batch(out, tmp_path, "--workers", "2", sweep="radius=0.1,0.2,-1,0.3")
    assert res.returncode == 2, res.stderr[-3000:]  # the variant with a negative radius failed …
    failures = json.loads((out / "manifest.json").read_text())["failures"]
    assert [f["file"] for f in failures] == ["cubic__n-2__radius--1.stl"]
    assert "failed cubic__n-2__radius--1.stl" in res.stderr and "Traceback" not in res.stderr
    outputs = check_outputs(out, 3)  # … and the others were written
    pids = [e["worker_pid"] for e in outputs]
    assert os.getpid() not in pids and len(pids) > len(set(pids))  # in worker processes, several tasks per worker
    again = run_batch(out, tmp_path, "--workers", "2")
    assert again.returncode == 0, again.stderr[-3000:]
    assert json.loads(again.stdout[again.stdout.index("{"):])["skipped"] == 3


def test_real_scheduler_and_worker_process(tmp_path):
    path = [str(ROOT / "core"), str(ROOT), os.environ.get("PYTHONPATH", "")]
    env = {"BLENDER_USER_RESOURCES": str(tmp_path / "worker-user"), "PYTHONPATH": os.pathsep.join(path)}
    with dask_cluster(tmp_path, workers=1, env=env, worker_args=("--preload", "ple_addon.batch")) as (address, procs):
        res = run_batch(tmp_path / "out", tmp_path, "--scheduler", address, sweep="radius=0.1,0.2")
        assert res.returncode == 0, res.stderr[-3000:]
        outputs = check_outputs(tmp_path / "out", 2)
        assert {e["worker_pid"] for e in outputs} == {procs[1].pid}  # the dask worker process ran bpy


def test_template_blend_and_saved_variants_in_one_process(tmp_path):
    template = tmp_path / "template.blend"
    make = ("import bpy; bpy.ops.wm.read_homefile(use_empty=True); "
            "cam = bpy.data.objects.new('Camera', bpy.data.cameras.new('Camera')); "
            "bpy.context.scene.collection.objects.link(cam); "
            f"bpy.ops.wm.save_as_mainfile(filepath={str(template)!r})")
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender-user"))
    subprocess.run([sys.executable, "-c", make], check=True, capture_output=True, timeout=300, env=env)
    out = tmp_path / "out"
    res = run_batch(out, tmp_path, "--scheduler", "sync", "--blend", str(template), "--save-blend",
                    sweep="radius=0.1,0.2")
    assert res.returncode == 0, res.stderr[-3000:]
    outputs = check_outputs(out, 2, objects_at_start=1)  # the template's camera, and nothing of the other variant
    for entry in outputs:
        saved = out / entry["blend"]
        probe = ("import bpy, sys; bpy.ops.wm.open_mainfile(filepath=sys.argv[1]); "
                 "print(sorted(o.type for o in bpy.data.objects))")
        listing = subprocess.run([sys.executable, "-c", probe, str(saved)], capture_output=True, text=True,
                                 timeout=300, env=env).stdout
        assert "'CAMERA'" in listing and "'MESH'" in listing


@pytest.mark.parametrize("flags, message", [(["--param", "size=3"], "unknown parameter"),
                                            (["--scheduler", "tcp://127.0.0.1:9"], "cannot reach the scheduler"),
                                            (["--blend", "/nonexistent.blend"], "no such file")])
def test_bad_input_exits_2(tmp_path, flags, message):
    res = run_batch(tmp_path / "out", tmp_path, *flags)
    assert res.returncode == 2
    assert message in res.stderr and "Traceback" not in res.stderr
