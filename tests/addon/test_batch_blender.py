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
from dask.distributed import Client
from daskcluster import dask_cluster, in_flight, kill_when, on_terminal
from ple.app import pipeline
from ple.program.sources import load_lattice

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.e2e  # each test starts Dask workers that install the extension themselves


def batch_argv(out: Path, *extra: str, sweep: str = "radius=0.1,0.2,0.3", n: int = 2) -> list[str]:
    return [sys.executable, "-m", "ple_addon.batch", "--program", "cubic", "--param", f"n={n}", "--param", sweep,
            "--style", "cnt", "--out", str(out), *extra]


def batch_env(tmp: Path) -> dict:
    return dict(os.environ, BLENDER_USER_RESOURCES=str(tmp / "blender-user"))


def run_batch(out: Path, tmp: Path, *extra: str, sweep: str = "radius=0.1,0.2,0.3",
              n: int = 2) -> subprocess.CompletedProcess:
    return subprocess.run(batch_argv(out, *extra, sweep=sweep, n=n), cwd=ROOT, capture_output=True, text=True,
                          timeout=900, env=batch_env(tmp))


def check_outputs(out: Path, count: int, objects_at_start: int = 0, n: int = 2) -> list:
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["engine"] == "blender"
    assert len(manifest["outputs"]) == count
    for entry in manifest["outputs"]:
        mesh = trimesh.load(out / entry["file"])
        # the core's one pipeline, as ple mesh writes it (float32 grid): Tessellate draws these triangles
        lat = load_lattice("cubic", {"n": n, "radius": entry["params"]["radius"]})
        truth = trimesh.Trimesh(*pipeline.mesh(pipeline.plan(pipeline.MeshRequest(lat, None, "cnt"))), process=False)
        assert mesh.is_watertight
        assert len(mesh.faces) == len(truth.faces) == entry["triangles"]
        assert abs(mesh.volume - truth.volume) <= 1e-6 * truth.volume
        assert entry["objects_at_start"] == objects_at_start  # each task began from a clean Blender state
    return manifest["outputs"]


def test_embedded_cluster_exports_the_core_meshes_reports_failures_and_resumes(tmp_path):
    out = tmp_path / "out"
    # one worker process: two installing the extension side by side are the killed-worker test's
    res = run_batch(out, tmp_path, "--workers", "1", sweep="radius=0.1,0.2,-1,0.3")
    assert res.returncode == 2, res.stderr[-3000:]  # the variant with a negative radius failed …
    failures = json.loads((out / "manifest.json").read_text())["failures"]
    assert [f["file"] for f in failures] == ["cubic__n-2__radius--1.stl"]
    assert "failed cubic__n-2__radius--1.stl" in res.stderr and "Traceback" not in res.stderr
    outputs = check_outputs(out, 3)  # … and the others were written
    pids = [e["worker_pid"] for e in outputs]
    assert os.getpid() not in pids and len(pids) > len(set(pids))  # in worker processes, several tasks per worker
    again = run_batch(out, tmp_path, "--workers", "1")
    assert again.returncode == 0, again.stderr[-3000:]
    assert json.loads(again.stdout[again.stdout.index("{"):])["skipped"] == 3


def blender_workers(tmp: Path, workers: int):
    """``dask_cluster`` whose workers can run Blender tasks: ``ple_addon.batch`` preloaded (bpy
    imported on their main thread), Blender's user resources in ``tmp``."""
    path = [str(ROOT / "core"), str(ROOT), os.environ.get("PYTHONPATH", "")]
    env = {"BLENDER_USER_RESOURCES": str(tmp / "worker-user"), "PYTHONPATH": os.pathsep.join(path)}
    return dask_cluster(tmp, workers=workers, env=env, worker_args=("--preload", "ple_addon.batch"))


def test_real_scheduler_and_worker_process(tmp_path):
    """On a terminal, the Blender door shows Dask's progress bar on stderr (this scheduler has no
    dashboard: no address is printed) and its JSON summary alone on stdout."""
    with blender_workers(tmp_path, 1) as (address, procs):
        code, out, err = on_terminal(batch_argv(tmp_path / "out", "--scheduler", address, sweep="radius=0.1,0.2"),
                                     batch_env(tmp_path), ROOT)
        assert code == 0, err[-3000:]
        assert json.loads(out)["written"] == 2
        assert "blender batch [" in err and "| 100% Completed |" in err and "dashboard" not in err
        outputs = check_outputs(tmp_path / "out", 2)
        assert {e["worker_pid"] for e in outputs} == {procs[1].pid}  # the dask worker process ran bpy


def test_a_killed_worker_loses_no_variant(tmp_path):
    """One of two ``dask worker`` processes SIGKILLed while it has a variant in flight: its
    variants are exported again by the other, every file equals the one-process run's, and no
    half-written file remains."""
    sweep, count = "radius=0.1:0.3:6", 6  # variants of a few hundred ms each (n=8): the kill lands mid-job
    out = tmp_path / "out"
    with blender_workers(tmp_path, 2) as (address, procs), Client(address, timeout=30) as client:
        with subprocess.Popen(batch_argv(out, "--scheduler", address, sweep=sweep, n=8), cwd=ROOT, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=batch_env(tmp_path)) as job:
            def some_done_and_w1_busy() -> bool:
                manifest = out / "manifest.json"
                return (manifest.is_file() and bool(json.loads(manifest.read_text())["outputs"])
                        and bool(in_flight(client)["w1"]))

            try:
                killed = kill_when(procs[2], some_done_and_w1_busy)
                stdout, stderr = job.communicate(timeout=600)
            finally:
                job.kill()
    assert job.returncode == 0, stderr[-3000:]
    assert json.loads(stdout[stdout.index("{"):])["written"] == count
    outputs = check_outputs(out, count, n=8)
    # files written after the killed worker was reaped: only the survivor can have written them (a
    # variant whose result died with its worker is run again there; the manifest may still name the
    # first run's worker, whose identical bytes it replaced)
    after = [e for e in outputs if (out / e["file"]).stat().st_mtime > killed]
    assert after and procs[1].pid in {e["worker_pid"] for e in outputs}  # the survivor went on after the kill
    assert not [p.name for p in out.iterdir() if ".part" in p.name]  # no half-written file
    ref = run_batch(tmp_path / "ref", tmp_path, "--scheduler", "sync", sweep=sweep, n=8)
    assert ref.returncode == 0, ref.stderr[-3000:]
    assert {e["file"]: (out / e["file"]).read_bytes() for e in outputs} == \
        {e["file"]: (tmp_path / "ref" / e["file"]).read_bytes() for e in outputs}


def test_template_blend_and_saved_variants_in_one_process(tmp_path):
    template = tmp_path / "template.blend"
    make = ("import bpy; bpy.ops.wm.read_homefile(use_empty=True); "
            "cam = bpy.data.objects.new('Camera', bpy.data.cameras.new('Camera')); "
            "bpy.context.scene.collection.objects.link(cam); "
            f"bpy.ops.wm.save_as_mainfile(filepath={str(template)!r})")
    env = batch_env(tmp_path)
    subprocess.run([sys.executable, "-c", make], check=True, capture_output=True, timeout=300, env=env)
    out = tmp_path / "out"
    res = run_batch(out, tmp_path, "--scheduler", "sync", "--blend", str(template), "--save-blend",
                    sweep="radius=0.1,0.2")
    assert res.returncode == 0, res.stderr[-3000:]
    outputs = check_outputs(out, 2, objects_at_start=1)  # the template's camera, and nothing of the other variant
    probe = ("import bpy, sys\n"
             "for path in sys.argv[1:]:\n"
             "    bpy.ops.wm.open_mainfile(filepath=path)\n"
             "    print('objects:', sorted(o.type for o in bpy.data.objects))")
    saved = [str(out / entry["blend"]) for entry in outputs]  # each opened in turn by one Blender
    listing = subprocess.run([sys.executable, "-c", probe, *saved], capture_output=True, text=True, timeout=300,
                             env=env).stdout
    found = [line for line in listing.splitlines() if line.startswith("objects:")]
    assert len(found) == len(saved) and all("'CAMERA'" in line and "'MESH'" in line for line in found), listing


@pytest.mark.parametrize("flags, message", [(["--param", "size=3"], "unknown parameter"),
                                            (["--scheduler", "tcp://127.0.0.1:9"], "cannot reach the scheduler"),
                                            (["--blend", "/nonexistent.blend"], "no such file")])
def test_bad_input_exits_2(tmp_path, flags, message):
    res = run_batch(tmp_path / "out", tmp_path, *flags)
    assert res.returncode == 2
    assert message in res.stderr and "Traceback" not in res.stderr
