"""The extension in the Blender users have (issue 37): a venv holding only ``bpy==5.0.1`` (its own
numpy, requests, zstandard; no scipy, manifold3d, rtree, trimesh, no ``ple``) with the zip
installed. Body fill, skin, unclean Export and Tessellate, LiL on a curved lattice, Check and the
CLG preview run there from the zip's own wheels (``bpy_only_cases.py``); what they made is checked
here against this checkout's core, run in this process or as ``ple`` commands.

The venv is ``build/bpy-venv`` (``make test-blender`` creates it: ``pip install bpy==5.0.1``);
without it these tests skip, saying how to make it. They run in ``make test-blender`` (which
``.ci/run`` calls after ``make test``), not in ``make test``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from blender_worker import Worker
from test_addon_doors import triangle_set

ROOT = Path(__file__).resolve().parents[2]
BPY_PYTHON = Path(os.environ.get("PLE_BPY_ONLY_PYTHON", ROOT / "build" / "bpy-venv" / "bin" / "python"))
HERE = Path(__file__).resolve().parent
pytestmark = pytest.mark.bpy_only


def _bpy_only_env() -> dict:
    """This environment without anything that would let the worker find this checkout's or this
    venv's packages."""
    drop = ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP", "PYTHONUSERBASE")
    env = {k: v for k, v in os.environ.items() if k not in drop}
    return dict(env, PLE_WORKER_TRUTH="none", PYTHONNOUSERSITE="1")


@pytest.fixture(scope="module")
def bare_blender(zip_path):
    if not BPY_PYTHON.exists():
        pytest.skip(f"no bpy-only Python at {BPY_PYTHON} (make test-blender creates it)")
    foreign = ("scipy", "manifold3d", "rtree", "trimesh", "ple")
    probe = subprocess.run([str(BPY_PYTHON), "-c", "import importlib.util as u, sys; "
                            f"sys.exit(any(u.find_spec(m) for m in {foreign!r}))"],
                           env=_bpy_only_env(), cwd="/", capture_output=True, text=True)
    assert probe.returncode == 0, f"{BPY_PYTHON} is not bpy-only: it can import one of {', '.join(foreign)}"
    worker = Worker(zip_path, python=str(BPY_PYTHON), env=_bpy_only_env())
    yield worker
    worker.stop()


def run(bare_blender, tmp_path: Path, case: str) -> None:
    ok, log = bare_blender.run(str(HERE / "bpy_only_cases.py"), case, tmp_path)
    assert ok, log[-8000:]


def ple_cli(*args, ok=(0,)) -> subprocess.CompletedProcess:
    res = subprocess.run([sys.executable, "-m", "ple.cli", *map(str, args)], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT / "core")}, timeout=600)
    assert res.returncode in ok, (args, res.stdout, res.stderr)
    return res


def test_the_packages_come_from_the_zip(bare_blender, tmp_path):
    run(bare_blender, tmp_path, "wheels_from_the_zip")
    where = json.loads((tmp_path / "modules.json").read_text())
    for name, path in where.items():
        assert "extensions" in path and str(ROOT) not in path and sys.prefix not in path, (name, path)


def test_unclean_export_and_tessellate_are_ple_mesh(bare_blender, tmp_path):
    run(bare_blender, tmp_path, "unclean_export_and_tessellate")
    made = json.loads((tmp_path / "crossing.json").read_text())
    ple_cli("mesh", tmp_path / "crossing.py", "--region", made["region"], "--style", "cnt",
            "--out", tmp_path / "cli.stl")
    mine, theirs = triangle_set(tmp_path / "crossing.stl"), triangle_set(tmp_path / "cli.stl")
    assert len(mine) and np.array_equal(mine, theirs)  # the same triangles (as sets of corners)
    mesh = trimesh.load(tmp_path / "crossing.stl")
    assert mesh.is_watertight and made["faces"] == len(mesh.faces)
    assert "unclean" in made["status"]


def test_body_fill_and_skin(bare_blender, tmp_path):
    from ple.filters.body import BodyFilter
    from ple.filters.cleanup import cleanup
    from ple.io.bodyfile import body_from_trimesh
    from ple.meshing.tessellate import tessellate
    from ple.program.sources import load_lattice

    run(bare_blender, tmp_path, "body_fill_and_skin")
    co, tris = json.loads((tmp_path / "body.json").read_text())
    body = body_from_trimesh(trimesh.Trimesh(co, tris))
    made = json.loads((tmp_path / "fill.json").read_text())
    lat = load_lattice("cubic")
    region = "0:10,0:10,0:10"
    assert made["inside"] == len(lat.with_filter(BodyFilter(body, "inside")).evaluate(region).center) > 0
    cleaned, _ = cleanup(lat.with_filter(BodyFilter(body, "any")), region, skin=0.3)
    assert made["any_cleaned"] == len(cleaned.evaluate(region).center)
    assert made["cut_faces"] == len(tessellate(cleaned, region, "cnt").faces)
    assert made["skin_faces"] > 0 and 2 * made["skin_edges"] == 3 * made["skin_faces"]  # closed


def test_lil_on_a_curved_lattice(bare_blender, tmp_path):
    from ple.filters import lil
    from ple.program.sources import load_lattice

    run(bare_blender, tmp_path, "lil_on_a_curved_lattice")
    made = json.loads((tmp_path / "lil.json").read_text())
    want = lil(load_lattice("cylindrical"), load_lattice("fig6_3")).evaluate("0:6,0:6,0:2")
    assert made["kept"] == len(want.center) > 0


def test_check_is_ple_check(bare_blender, tmp_path):
    run(bare_blender, tmp_path, "check")
    made = json.loads((tmp_path / "check.json").read_text())
    cli = json.loads(ple_cli("check", tmp_path / "check.py", "--region", made["region"], "--json",
                             "--min-feature", "0.2", ok=(0, 1)).stdout)  # 1: a rule failed
    assert made["rules"]["clean"]["count"] == cli["rules"]["clean"]["count"] > 0
    assert {k: v["ok"] for k, v in made["rules"].items()} == {k: v["ok"] for k, v in cli["rules"].items()}


def test_clg_preview(bare_blender, tmp_path):
    run(bare_blender, tmp_path, "clg_preview")
    made = json.loads((tmp_path / "clg.json").read_text())
    assert made["status"] == "" and made["polygons"] > 0 and made["vertices"] > 0


def test_every_preset_adds_tessellates_and_exports(bare_blender, tmp_path):
    from ple.program.presets import preset_names

    run(bare_blender, tmp_path, "every_preset")
    made = json.loads((tmp_path / "presets.json").read_text())
    assert sorted(made) == sorted(preset_names())
    for name, entry in made.items():
        mesh = trimesh.load(tmp_path / f"{name}.stl")
        assert len(mesh.faces) > 0 and entry["tessellated"] > 0, name
        assert mesh.is_watertight, name  # the default export style (refined) is a closed solid
