"""A signal stops `ple clg mesh` (nested materials included), `ple skin` and `ple mesh --fill any`
inside a long manifold3d Boolean: the Booleans run in a forked child (``ple.program.meshes``), which
the command kills on its way out; nothing is left on disk and the user's previous file is intact."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.cli.test_mesh_union_interrupt import interrupt_once_a_child_lives
from tests.io.test_reliability_files import default_signals

pytest.importorskip("manifold3d")

ROOT = Path(__file__).resolve().parents[2]
PRESET = ROOT / "presets" / "clg" / "beam_of_beams.json"


def _nested(tmp_path: Path) -> Path:
    """The beam-of-beams preset (a nested material in every beam) on 3 × 3 × 3 groups: seconds of
    Booleans, a few hundred MB."""
    doc = json.loads(PRESET.read_text())
    doc["pattern"]["W"] = {"count": 3, "similarity": {"kind": "translation", "vector": [0, 0, 2]}}
    src = tmp_path / "nested.json"
    src.write_text(json.dumps(doc))
    return src


def _interrupt(tmp_path: Path, args: list, sig) -> None:
    """Run ``ple ARGS --out m.stl`` over a previous m.stl, signal it once its Booleans' child has
    lived a second (a lattice program's child lives a moment), and check how it ended."""
    out = tmp_path / "m.stl"
    out.write_text("previous")
    before = sorted(p.name for p in tmp_path.iterdir())
    ple = Path(sys.executable).parent / "ple"
    proc = subprocess.Popen([str(ple), *map(str, args), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    child = interrupt_once_a_child_lives(proc, sig, 120)
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert out.read_text() == "previous"
    assert not os.path.exists(f"/proc/{child}") or "Z" in Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_during_a_clg_boolean_ends_the_mesh(tmp_path, sig):
    _interrupt(tmp_path, ["clg", "mesh", _nested(tmp_path), "--max-memory", "8G"], sig)


def test_signal_during_a_skin_ends_it(tmp_path):
    _interrupt(tmp_path, ["skin", "cubic", "--param", "n=8", "--body", ROOT / "presets" / "bracket.stl",
                          "--thickness", "0.3"], signal.SIGTERM)


def test_signal_during_a_body_cut_ends_the_mesh(tmp_path):
    """The lattice filling the bracket by 'any' is cut at its surface by Booleans of about 5 s."""
    _interrupt(tmp_path, ["mesh", "cubic", "--param", "n=8", "--body", ROOT / "presets" / "bracket.stl", "--fill",
                          "any"], signal.SIGTERM)


def test_the_contained_body_cut_is_the_in_process_one():
    from functools import partial

    import trimesh
    from ple.filters.body import Body
    from ple.meshing.skin import clip_to_bodies
    from ple.meshing.tessellate import tessellate
    from ple.program.meshes import mesh_contained
    from ple.program.sources import load_lattice

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.3)
    sphere.apply_translation((1, 1, 1))
    body = Body(sphere.vertices, sphere.faces)
    mesh = tessellate(load_lattice("cubic", {"n": 3}), style="cnt")
    here = clip_to_bodies(mesh, [body])
    there = clip_to_bodies(mesh, [body], partial(mesh_contained, name="cubic", what="the cut"))
    assert np.array_equal(here.vertices, there.vertices) and np.array_equal(here.faces, there.faces)
    assert 0 < len(here.faces) and here.is_watertight and there.metadata["ple_cut_by"] == [body]


def test_the_contained_clg_mesh_is_the_in_process_one(tmp_path):
    from ple.clg.ir import clg_from_dict
    from ple.clg.query import compiled
    from ple.meshing.clg import mesh_arrays
    from ple.program.meshes import mesh_clg_contained

    comp = compiled(clg_from_dict(json.loads(PRESET.read_text())))
    v, f = mesh_clg_contained(comp, 16, None, "beam_of_beams")
    w, g = mesh_arrays(comp, 16)
    key = lambda v, f: sorted(map(tuple, v[f].reshape(-1, 9).round(12)))  # noqa: E731 - face order may differ
    assert key(v, f) == key(w, g)
