"""A signal stops `ple clg mesh` inside a long manifold3d Boolean, nested materials included: the
Booleans run in a forked child (``ple.program.meshes.mesh_clg_contained``), which the command kills
on its way out; nothing is left on disk and the user's previous file is intact."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.cli.test_mesh_union_interrupt import _children
from tests.io.test_reliability_files import default_signals

pytest.importorskip("manifold3d")

PRESET = Path(__file__).resolve().parents[2] / "presets" / "clg" / "beam_of_beams.json"


def _nested(tmp_path: Path) -> Path:
    """The beam-of-beams preset (a nested material in every beam) on 3 × 3 × 3 groups: seconds of
    Booleans, a few hundred MB."""
    doc = json.loads(PRESET.read_text())
    doc["pattern"]["W"] = {"count": 3, "similarity": {"kind": "translation", "vector": [0, 0, 2]}}
    src = tmp_path / "nested.json"
    src.write_text(json.dumps(doc))
    return src


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_during_a_clg_boolean_ends_the_mesh(tmp_path, sig):
    src = _nested(tmp_path)
    out = tmp_path / "m.stl"
    out.write_text("previous")
    ple = Path(sys.executable).parent / "ple"
    proc = subprocess.Popen([str(ple), "clg", "mesh", str(src), "--max-memory", "8G", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    deadline = time.monotonic() + 120
    while True:  # the Booleans' child, alive for a second: inside manifold3d by now
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.poll() else "no child"
        kids = _children(proc.pid)
        if kids:
            child = kids[0]
            time.sleep(1.0)
            if os.path.exists(f"/proc/{child}"):
                break
        time.sleep(0.05)
    t0 = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - t0
    assert proc.returncode == 128 + sig and "interrupted" in err and "Traceback" not in err, err
    assert took < 5, took  # not a benchmark: the Booleans left would take seconds more
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.stl", "nested.json"]
    assert out.read_text() == "previous"
    assert not os.path.exists(f"/proc/{child}") or "Z" in Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1]


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
