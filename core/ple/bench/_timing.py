"""Timing and memory helpers for benchmarks."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

from ..errors import PleError


def best_of(fn, repeat: int = 3) -> float:
    """Best wall time in seconds of ``repeat`` calls of ``fn()``."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _pss(pid: int) -> int:
    """Proportional set size of a process in bytes (0 once it is gone): shared pages split
    between parent and forked child, so their sum is what they hold together."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as fh:
            for line in fh:
                if line.startswith("Pss:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(x) for x in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


def peak_pss(cmd: list[str], every: float = 0.01) -> dict:
    """Run ``cmd`` and sample the summed PSS of it and its children every ``every`` seconds
    (Linux ``/proc``): {"returncode", "peak_bytes", "seconds", "stdout", "stderr"}."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = 0
    while proc.poll() is None:
        peak = max(peak, sum(_pss(p) for p in [proc.pid, *_children(proc.pid)]))
        time.sleep(every)
    out, err = proc.communicate()
    return {"returncode": proc.returncode, "peak_bytes": peak, "seconds": time.perf_counter() - t0,
            "stdout": out.strip(), "stderr": err.strip()}


def checkout(rev: str, into: Path, *paths: str) -> Path:
    """``paths`` of the repository holding this package at ``rev``, extracted into ``into``
    (``git archive``): a benchmark's baseline, today's code beside ours in the same run."""
    root = Path(__file__).resolve().parents[3]
    try:
        archive = subprocess.run(["git", "-C", str(root), "archive", rev, *paths], capture_output=True,
                                 check=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        raise PleError(f"--baseline-rev {rev}: cannot read it from the repository ({exc})") from None
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    return into
