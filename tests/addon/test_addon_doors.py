"""Every door gives the same mesh (issue 37): the add-on's Export writes the triangle set that
``ple mesh`` writes for the same lattice, region and style, for clean, unclean (crossing
diagonals, shrunk junctions), filtered, Möbius and body-cut lattices; and every preset of the Add
menu adds, tessellates and exports with its defaults (``test_bpy_only.py``, in the Blender users
have).

The command line runs in its own process (``python -m ple.cli`` with this checkout's core), so
the comparison is between two doors, not one function called twice."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_addon import new_rig

ROOT = Path(__file__).resolve().parents[2]
CASES = ["same_triangles_every_door"]  # every preset in every door: test_bpy_only.py

CROSSING = '''

def lattice():
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.13)
    for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0)):
        lat.add_beam(a, a, *d)
    lat.set_u(4, Translation(Vec(1, 0, 0)))
    lat.set_v(4, Rotation(0.025, Vec(0, 0, 1), Pt(0, -40, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 1)))
    return lat
'''

SHRUNK = '''
def lattice():
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.12)
    b = lat.add_node(Pt(0.2, 0, 0), 0.12)
    lat.add_beam(a, b, 0, 0, 0)
    lat.add_beam(b, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 0, 0, 1)
    lat.set_u(4, Scaling(1.025, Pt(-16, 0, 0)))
    lat.set_v(3, Translation(Vec(0, 0.4, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 0.4)))
    return lat
'''


@pytest.mark.parametrize("case", CASES)
def test_doors(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
bpy = ple_ext = core = None


def ple_cli(*args) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "core")}
    res = subprocess.run([sys.executable, "-m", "ple.cli", *map(str, args)], capture_output=True, text=True,
                         env=env, timeout=600)
    assert res.returncode == 0, (args, res.stdout, res.stderr)
    return res


def triangle_set(path: Path) -> np.ndarray:
    """The triangles of a binary STL, each as its three float32 corners rotated to start at the
    smallest (orientation kept), sorted: two files hold the same triangles iff these are equal."""
    data = path.read_bytes()
    n = int(np.frombuffer(data, "<u4", 1, 80)[0])
    rec = np.frombuffer(data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), n, 84)
    tri = rec["v"].copy()
    keys = [tuple(map(tuple, t)) for t in tri]
    first = np.array([min(range(3), key=lambda i, k=k: k[i]) for k in keys])
    tri = tri[np.arange(n)[:, None], (first[:, None] + np.arange(3)) % 3]
    flat = tri.reshape(n, 9)
    return flat[np.lexsort(flat.T[::-1])]


def same_as_cli(rig, source, tmp: Path, label: str, style: str = "CNT", whole: bool = False) -> np.ndarray:
    """Export ``rig`` from the add-on and mesh ``source`` (a file or preset) with ``ple mesh`` over the
    rig's region (``whole``: the whole lattice); assert the two files hold the same triangles;
    returns them."""
    model = ple_ext.rig.model
    region = None if whole else model.region_of(rig, model.shown_lattice(rig))
    mine, theirs = tmp / f"{label}.addon.stl", tmp / f"{label}.cli.stl"
    assert bpy.ops.ple.export(filepath=str(mine), style=style) == {"FINISHED"}, label
    where = ["--region", str(region)] if region else []
    ple_cli("mesh", source, *where, "--style", style.lower().replace("_", "-"), "--out", theirs)
    a, b = triangle_set(mine), triangle_set(theirs)
    assert len(a) > 0, label
    assert a.shape == b.shape and np.array_equal(a, b), (label, a.shape, b.shape)
    return a


def from_file(path: Path, **kw):
    assert bpy.ops.ple.lattice_add(source="FILE", filepath=str(path), **kw) == {"FINISHED"}
    return bpy.context.active_object


def case_same_triangles_every_door():
    tmp = Path.cwd()
    # clean: no unclean hub, the status stays empty
    rig = new_rig("cubic")
    same_as_cli(rig, "cubic", tmp, "clean")
    assert rig.ple.status == "", rig.ple.status
    # unclean, crossing diagonals: united locally; the rig says so
    (tmp / "crossing.py").write_text(CROSSING)
    rig = from_file(tmp / "crossing.py")
    tri = same_as_cli(rig, tmp / "crossing.py", tmp, "crossing")
    assert "unclean" in rig.ple.status, rig.ple.status
    assert len(tri) > 0
    # unclean, shrunk junctions (beams shorter than their junctions), in chocc too
    (tmp / "shrunk.py").write_text(SHRUNK)
    rig = from_file(tmp / "shrunk.py")
    same_as_cli(rig, tmp / "shrunk.py", tmp, "shrunk")
    assert "unclean" in rig.ple.status, rig.ple.status
    same_as_cli(rig, tmp / "shrunk.py", tmp, "shrunk_chocc", style="CHOCC")
    # filtered: the IR of cubic (written by ple ir) with a stencil filter
    ple_cli("ir", "cubic", "--out", tmp / "cubic.json")
    data = json.loads((tmp / "cubic.json").read_text())
    data["filter"] = {"stencil": {"shape": [2, 2, 2], "cells": [1, 0, 0, 1, 0, 1, 1, 1]}}
    (tmp / "stencil.json").write_text(json.dumps(data))
    rig = from_file(tmp / "stencil.json")
    filtered = same_as_cli(rig, tmp / "stencil.json", tmp, "filtered")
    whole = triangle_set(tmp / "clean.cli.stl")
    assert 0 < len(filtered) < len(whole)  # the filter took something away
    # Möbius: the preset menu routes it to the Möbius rig, meshed whole
    rig = new_rig("mobius_slab")
    same_as_cli(rig, "mobius_slab", tmp, "mobius", whole=True)
    # body-cut: a BCC filling the bracket (its body shipped with the preset)
    rig = new_rig("bracket_fill")
    same_as_cli(rig, "bracket_fill", tmp, "bracket")

