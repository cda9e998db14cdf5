"""Helpers of the reliability tests: run ``ple`` in a subprocess under a memory watchdog."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import psutil

CORE = str(Path(__file__).resolve().parents[1] / "core")
WATCHDOG_BYTES = 3 << 30  # address-space cap of the child: a runaway fails instead of filling RAM
PEAK_LIMIT_BYTES = 2 << 30  # the promise (docs/reliability.md): every listed input stays under 2 GB


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str
    peak_rss: int  # bytes: the largest resident set of the command and the children it waited for


def _cap() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (WATCHDOG_BYTES, WATCHDOG_BYTES))


def ple(*args, cwd=None, env=None) -> Run:
    """``python -m ple.cli ARGS`` with this checkout's core, under the watchdog."""
    full_env = {**os.environ, "PYTHONPATH": CORE, **(env or {})}
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen([sys.executable, "-m", "ple.cli", *map(str, args)], cwd=cwd, env=full_env,
                                stdout=out, stderr=err, text=True, preexec_fn=_cap)
        try:
            _, status, usage = os.wait4(proc.pid, 0)  # this child's own peak (with its waited children)
        except BaseException:
            proc.kill()
            raise
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        return Run(proc.returncode, out.read(), err.read(), usage.ru_maxrss * 1024)


def assert_clean_failure(run: Run, *needles: str) -> None:
    """Exit 2 with one line on stderr, no traceback, naming every needle."""
    assert run.returncode == 2, (run.returncode, run.stderr)
    assert "Traceback" not in run.stderr, run.stderr
    lines = [x for x in run.stderr.strip().splitlines() if x]
    assert len(lines) == 1, run.stderr
    for n in needles:
        assert n in run.stderr, (n, run.stderr)


def gone(pid: int) -> bool:
    """Whether process ``pid`` has ended: it no longer exists, or is a zombie waiting for init."""
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True
