"""A program's whole process tree ends with its run (docs/reliability.md, *Contained programs*):
a lattice program that forks, forks twice, starts a new session or daemonises a grandchild, and
then raises, returns or runs past its time limit, leaves no process behind, and a caller reading
``ple``'s output (``subprocess.run(capture_output=True)``) gets it when ``ple`` ends, not when
the grandchild would have. The grandchildren write their pids to a file; after the run each of
them must be gone (psutil), which no timing decides."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import psutil
import pytest
from ple.errors import PleError
from ple.program import proctree
from ple.program.runner import Job
from reliability_helpers import CORE, gone

SLEEP = 120  # seconds a grandchild sleeps: far beyond every guard below
GUARD = 60  # the longest a run may take before the test fails (the runs end within a second or the --timeout)

# how the program starts the process that sleeps; each writes the sleeper's pid on a line of PIDS
STARTS = {
    "fork": "if os.fork() == 0:\n        sleeper()\n",
    "double fork": "if os.fork() == 0:\n        if os.fork() == 0:\n            sleeper()\n        os._exit(0)\n",
    "setsid": "if os.fork() == 0:\n        os.setsid()\n        sleeper()\n",
    "daemon": ("if os.fork() == 0:\n        os.setsid()\n        if os.fork() == 0:\n            sleeper()\n"
               "        os._exit(0)\n"),
}
ENDS = {
    "raises": "raise ValueError('after starting a sleeper')",
    "returns": "lat = Lattice()\n    lat.add_node([0, 0, 0], 0.1)\n    return lat",
    "hangs": "while True:\n        pass",
}


def _program(tmp_path, start: str, end: str) -> tuple[str, str]:
    pids = tmp_path / "pids.txt"
    text = f"""import os, time
from ple.model.lattice import Lattice

def sleeper():
    with open({str(pids)!r}, "a") as fh:
        fh.write(f"{{os.getpid()}}\\n")
    time.sleep({SLEEP})
    os._exit(0)

def lattice():
    {STARTS[start]}    while not os.path.exists({str(pids)!r}) or not open({str(pids)!r}).read().endswith("\\n"):
        time.sleep(0.01)
    {ENDS[end]}
"""
    prog = tmp_path / "prog.py"
    prog.write_text(text)
    return str(prog), str(pids)


def _sleepers(pids: str) -> list[int]:
    with open(pids) as fh:
        return [int(x) for x in fh.read().split()]


@pytest.mark.parametrize("end", ENDS)
@pytest.mark.parametrize("start", STARTS)
def test_no_process_of_a_program_outlives_ple(tmp_path, start, end):
    prog, pids = _program(tmp_path, start, end)
    env = {**os.environ, "PYTHONPATH": CORE}
    run = subprocess.run([sys.executable, "-m", "ple.cli", "info", prog, "--timeout", "2"], capture_output=True,
                         text=True, env=env, timeout=GUARD)  # a sleeper holding stdout would exceed the guard
    if end == "returns":
        assert run.returncode == 0 and "1 x 1 x 1" in run.stdout, run.stderr
    else:
        assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
        assert len(run.stderr.strip().splitlines()) == 1, run.stderr
        assert ("after starting a sleeper" if end == "raises" else "ran longer than 2 s") in run.stderr
    sleepers = _sleepers(pids)
    assert sleepers and all(gone(p) for p in sleepers), sleepers


def _forking_work(pids: str, daemon: bool):
    def work():
        if os.fork() == 0:
            if daemon:
                os.setsid()
                if os.fork():
                    os._exit(0)
            with open(pids, "a") as fh:
                fh.write(f"{os.getpid()}\n")
            time.sleep(SLEEP)
            os._exit(0)
        while not os.path.exists(pids) or not open(pids).read().endswith("\n"):
            time.sleep(0.01)
        yield os.getpid()  # the child's
        return 42
    return work


@pytest.mark.parametrize("daemon", [False, True])
def test_a_job_ends_the_processes_its_work_started(tmp_path, daemon):
    pids = str(tmp_path / "pids.txt")
    assert Job(_forking_work(pids, daemon), "w", timeout=GUARD).result() == 42
    assert all(gone(p) for p in _sleepers(pids))


@pytest.mark.parametrize("daemon", [False, True])
def test_cancel_ends_the_whole_tree(tmp_path, daemon):
    pids = str(tmp_path / "pids.txt")

    def work():
        yield from _forking_work(pids, daemon)()
        while True:
            pass
    job = Job(work, "w", timeout=GUARD)
    taken = []
    while not taken:  # the sleeper has started once the work yields the child's pid
        job.poll(1.0)
        taken = job.take()
    child = taken[0]
    job.cancel()
    assert gone(child) and all(gone(p) for p in _sleepers(pids))


def test_a_child_that_dies_does_not_wait_for_its_grandchild(tmp_path):
    """The child is killed after forking a sleeper that holds its pipe: the pipe never reaches its
    end of file, yet the job ends, says how the child died, and the sleeper (in the child's
    session) is ended too."""
    pids = str(tmp_path / "pids.txt")

    def work():
        if os.fork() == 0:
            with open(pids, "a") as fh:
                fh.write(f"{os.getpid()}\n")
            time.sleep(SLEEP)
            os._exit(0)
        while not os.path.exists(pids) or not open(pids).read().endswith("\n"):
            time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGKILL)
    with pytest.raises(PleError, match="crashed with SIGKILL"):
        Job(work, "w", timeout=GUARD).result()
    assert all(gone(p) for p in _sleepers(pids))


def test_members_finds_descendants_and_the_session(tmp_path):
    """proctree.members of a detached child: its child and grandchild while it lives."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.close(r)
        proctree.detach()
        kid = os.fork()
        if kid == 0:
            grand = os.fork()
            if grand == 0:
                time.sleep(SLEEP)
                os._exit(0)
            os.write(w, f"{grand}\n".encode())
            time.sleep(SLEEP)
            os._exit(0)
        os.write(w, f"{kid}\n".encode())
        time.sleep(SLEEP)
        os._exit(0)
    os.close(w)
    with os.fdopen(r) as fh:
        expected = {int(fh.readline()), int(fh.readline())}
    try:
        assert proctree.members(pid) == expected
        assert os.getsid(pid) == pid and os.getpgid(pid) == pid
    finally:
        proctree.end_tree(pid)
    assert all(gone(p) for p in expected | {pid})


def test_without_proc_the_process_group_is_ended(tmp_path, monkeypatch):
    """Where /proc is missing (macOS), end_tree kills the child's process group: a grandchild that
    stays in it is ended too."""
    monkeypatch.setattr(proctree, "members", lambda pid: None)
    pids = str(tmp_path / "pids.txt")
    assert Job(_forking_work(pids, daemon=False), "w", timeout=GUARD).result() == 42
    assert all(gone(p) for p in _sleepers(pids))


def test_end_tree_leaves_a_process_that_is_not_its_child_alone():
    """A pid that is no longer (or never was) this process's child may name another process: it
    is neither signalled nor scanned."""
    shell = subprocess.Popen(["sh", "-c", f"sleep {SLEEP} & echo $!; wait"], stdout=subprocess.PIPE, text=True)
    try:
        grandchild = int(shell.stdout.readline())
        assert proctree.end_tree(grandchild) is None
        assert psutil.Process(grandchild).status() != psutil.STATUS_STOPPED and not gone(grandchild)
    finally:
        for p in psutil.Process(shell.pid).children():
            p.kill()
        shell.kill()
        shell.wait()
