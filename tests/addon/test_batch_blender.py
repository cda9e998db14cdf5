"""python -m ple_addon.batch: variants exported by background Blender match the core's meshes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import trimesh
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

ROOT = Path(__file__).resolve().parents[2]


def run_batch(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ple_addon.batch", "--program", "cubic", "--param", "n=2",
                           "--param", "radius=0.1,0.2", "--style", "cnt", "--out", str(out), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_blender_batch_exports_the_core_meshes_and_resumes(tmp_path):
    res = run_batch(tmp_path, "--format", "stl")
    assert res.returncode == 0, res.stderr[-2000:]
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["engine"] == "blender" and not manifest["failures"]
    assert len(manifest["outputs"]) == 2
    for entry in manifest["outputs"]:
        mesh = trimesh.load(tmp_path / entry["file"])
        truth = tessellate(load_lattice("cubic", entry["params"]), style="cnt")
        assert mesh.is_watertight
        assert len(mesh.faces) == len(truth.faces) == entry["triangles"]
        assert abs(mesh.volume - truth.volume) <= 1e-5 * truth.volume
    again = run_batch(tmp_path, "--format", "stl")
    assert again.returncode == 0
    assert json.loads(again.stdout[again.stdout.index("{"):])["skipped"] == 2


def test_blender_batch_bad_input_exits_2(tmp_path):
    res = run_batch(tmp_path, "--format", "stl", "--param", "size=3")
    assert res.returncode == 2
    assert "unknown parameter" in res.stderr and "Traceback" not in res.stderr
