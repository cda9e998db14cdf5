"""The extension in the Blender users have (issue 37): a venv holding only ``bpy==5.0.1`` (its own
numpy, requests, zstandard; no scipy, manifold3d, rtree, trimesh, no ``ple``) with the zip
installed. Body fill, skin, unclean Export and Tessellate, LiL on a curved lattice, Check and the
CLG preview run there from the zip's own wheels (``bpy_only_cases.py``), Export gives the triangles
``ple mesh`` writes for clean, unclean, filtered, Möbius and body-cut lattices, and every preset
adds, tessellates and exports; what they made is checked here against this checkout's core, run
in this process or as ``ple`` commands.

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


def triangle_set(path: Path) -> np.ndarray:
    """The triangles of a binary STL, each as its three float32 corners rotated to start at the
    smallest (orientation kept), sorted: two files hold the same triangles iff these are equal."""
    data = path.read_bytes()
    n = int(np.frombuffer(data, "<u4", 1, 80)[0])
    tri = np.frombuffer(data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), n, 84)["v"].copy()
    first = np.array([min(range(3), key=lambda i, t=t: tuple(t[i])) for t in tri], np.int64)
    tri = tri[np.arange(n)[:, None], (first[:, None] + np.arange(3)) % 3]
    flat = tri.reshape(n, 9)
    return flat[np.lexsort(flat.T[::-1])]


def test_same_triangles_every_door(bare_blender, tmp_path):
    """The add-on's file and ple mesh's file of the same lattice, region and style hold the same
    triangles: clean, crossing and shrunk (unclean), stencil-filtered, Möbius and body-cut."""
    ple_cli("ir", "cubic", "--out", tmp_path / "cubic.json")
    data = json.loads((tmp_path / "cubic.json").read_text())
    data["filter"] = {"stencil": {"shape": [2, 2, 2], "cells": [1, 0, 0, 1, 0, 1, 1, 1]}}
    (tmp_path / "stencil.json").write_text(json.dumps(data))
    run(bare_blender, tmp_path, "same_triangles_every_door")
    made = {e["label"]: e for e in json.loads((tmp_path / "doors.json").read_text())}
    for label, e in made.items():
        src = e["source"] if (tmp_path / e["source"]).suffix not in (".py", ".json") else tmp_path / e["source"]
        where = ["--region", e["region"]] if e["region"] else []
        ple_cli("mesh", src, *where, "--style", e["style"], "--out", tmp_path / f"{label}.cli.stl")
        mine, theirs = triangle_set(tmp_path / f"{label}.stl"), triangle_set(tmp_path / f"{label}.cli.stl")
        assert len(mine) > 0 and mine.shape == theirs.shape and np.array_equal(mine, theirs), label
    assert made["clean"]["status"] == ""
    assert all("unclean" in made[k]["status"] for k in ("crossing", "shrunk", "shrunk_chocc"))
    assert 0 < len(triangle_set(tmp_path / "filtered.stl")) < len(triangle_set(tmp_path / "clean.stl"))


def test_the_packages_come_from_the_zip(bare_blender, tmp_path):
    """The wheels' packages, the vendored core and its compiled modules (one per C source of the
    core, as fast as in ple's own venv) are imported from the installed zip."""
    import importlib.machinery

    compiled = [".".join(c.relative_to(ROOT / "core").with_suffix("").parts)
                for c in sorted((ROOT / "core" / "ple").rglob("*.c"))]
    assert compiled, "the core has C sources"
    (tmp_path / "compiled.json").write_text(json.dumps(compiled))
    run(bare_blender, tmp_path, "wheels_from_the_zip")
    where = json.loads((tmp_path / "modules.json").read_text())
    assert set(where) == {"scipy", "manifold3d", "rtree", "trimesh", "ple", *compiled}
    for name, path in where.items():
        assert "extensions" in path and str(ROOT) not in path and sys.prefix not in path, (name, path)
    for name in compiled:
        assert where[name].endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)), (name, where[name])


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


SHARDS = 2  # the presets in two halves, one per core (make test-blender runs two workers)


@pytest.mark.parametrize("shard", range(SHARDS))
def test_every_preset_adds_tessellates_and_exports(bare_blender, tmp_path, shard):
    from ple.program.presets import preset_names

    names = sorted(preset_names())[shard::SHARDS]
    (tmp_path / "shard.json").write_text(json.dumps(names))
    run(bare_blender, tmp_path, "every_preset")
    made = json.loads((tmp_path / "presets.json").read_text())
    assert sorted(made) == names
    for name, entry in made.items():
        mesh = trimesh.load(tmp_path / f"{name}.stl")
        assert len(mesh.faces) > 0 and entry["tessellated"] > 0, name
        assert mesh.is_watertight, name  # the default export style (refined) is a closed solid
