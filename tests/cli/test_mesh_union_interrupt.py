"""A signal stops `ple mesh` even inside a long union: large clusters are united in a forked child
(``ple.meshing.unions.unite_stoppable``), which the command kills on its way out; nothing is left
on disk and the user's previous file is intact."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.io.test_reliability_files import default_signals

pytest.importorskip("manifold3d")

THICK = """
def lattice(n: Range(2, 40) = 6):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.3)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    return lat
"""


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        text = (task / "children").read_text() if (task / "children").exists() else ""
        out += [int(x) for x in text.split()]
    return out


def interrupt_once_a_child_lives(proc, sig, wait: float) -> int:
    """Send ``sig`` to ``proc`` once one of its children has lived a second (within ``wait``
    seconds), and check that it ends within 2 s as interrupted (128 + sig, no traceback).
    Returns that child's pid."""
    deadline = time.monotonic() + wait
    seen: dict = {}  # child pid -> first seen
    while True:
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read() if proc.poll() else "no child"
        now = time.monotonic()
        seen = {k: seen.get(k, now) for k in _children(proc.pid)}
        old = [k for k, t in seen.items() if now - t > 1.0]
        if old:
            break
        time.sleep(0.05)
    t0 = time.monotonic()
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    took = time.monotonic() - t0
    assert proc.returncode == 128 + sig and "interrupted" in err and "Traceback" not in err, err
    assert took < 2, took  # not a benchmark: the work left would take seconds to minutes more
    return old[0]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_during_a_union_ends_the_mesh(tmp_path, sig):
    src = tmp_path / "thick.py"
    src.write_text(THICK)
    out = tmp_path / "t.stl"
    out.write_text("previous")
    ple = Path(sys.executable).parent / "ple"
    proc = subprocess.Popen([str(ple), "mesh", str(src), "--style", "cnt", "--workers", "1", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    child = interrupt_once_a_child_lives(proc, sig, 180)  # the union's child lives for minutes, the program's a moment
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.stl", "thick.py"]
    assert out.read_text() == "previous"
    assert not os.path.exists(f"/proc/{child}") or "Z" in Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1]
