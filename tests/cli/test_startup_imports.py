"""Small jobs pay only for the libraries they use: a clean ``ple mesh`` streamed to STL, ``ple
info`` and ``ple check`` import neither trimesh nor Dask (about half a second each). The formats
meshed in memory (PLY, OBJ, 3MF, GLB) still hold the mesh in a trimesh."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("trimesh", "dask", "distributed", "scipy.spatial", "manifold3d", "rtree")
PROBE = f"""
import json, sys
from ple.cli.main import main
code = main(sys.argv[1:])
print(json.dumps({{"code": code, "heavy": sorted(m for m in {HEAVY!r} if m in sys.modules)}}), file=sys.stderr)
"""


def run(*argv):
    proc = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, timeout=120)
    return json.loads(proc.stderr.strip().splitlines()[-1]), proc


@pytest.mark.parametrize("argv", [
    ("mesh", "cubic", "--style", "cnt", "--out", "{tmp}/c.stl"),
    ("mesh", "cubic", "--param", "n=3", "--out", "{tmp}/r.stl"),
    ("info", "cubic"),
    ("check", "cubic"),
], ids=["mesh-cnt-stl", "mesh-refined-stl", "info", "check"])
def test_a_small_job_imports_no_heavy_library(tmp_path, argv):
    out, proc = run(*(a.format(tmp=tmp_path) for a in argv))
    assert out["code"] == 0, proc.stderr[-2000:]
    assert out["heavy"] == [], out


def test_the_lazily_imported_libraries_still_serve_the_formats_that_need_them(tmp_path):
    """GLB is encoded by trimesh: imported where it is needed, and the file reads back closed."""
    import trimesh

    out, proc = run("mesh", "cubic", "--param", "n=2", "--style", "cnt", "--out", str(tmp_path / "c.glb"))
    assert out["code"] == 0, proc.stderr[-2000:]
    assert "trimesh" in out["heavy"]
    mesh = trimesh.load(tmp_path / "c.glb", force="mesh")
    assert len(mesh.faces) > 0 and mesh.is_watertight
