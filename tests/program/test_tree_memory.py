"""``--max-memory`` bounds a program's whole process tree (docs/reliability.md, *Contained
programs*): a program that forks three children, each holding 150 MiB and so each under a limit
of 300 MiB, is stopped with its whole tree and an error naming the tree's total and its process
count; under 2 GiB it runs to its end, as does one process holding 150 MiB under 300 MiB. Pages a
fork shares with its parent count once. The children's pids are written to a file by the
program; after the run each must be gone, which no timing decides."""

from __future__ import annotations

import inspect
import os
import time

import pytest
from ple.errors import PleError
from ple.program import proctree
from ple.program.runner import Hints, Job
from reliability_helpers import assert_clean_failure, gone, ple

MIB = 1 << 20
HOLD = 60  # seconds a child holds its memory when the watch is to stop it: far beyond any run below

pytestmark = pytest.mark.skipif(not proctree.TREE_MEMORY, reason="a tree's memory is watched through /proc")


def hold(mib: int, seconds: float) -> None:
    """Allocate ``mib`` MiB, touch every page (so that it is resident), keep it ``seconds``."""
    block = bytearray(mib * MIB)
    for i in range(0, len(block), 4096):
        block[i] = 1
    time.sleep(seconds)


def workers(count: int, mib: int, seconds: float, pids: str) -> None:
    """Fork ``count`` children that each ``hold`` ``mib`` MiB, write their pids to ``pids``, wait."""
    kids = []
    for _ in range(count):
        pid = os.fork()
        if pid == 0:  # pragma: no cover - a forked child
            hold(mib, seconds)
            os._exit(0)
        kids.append(pid)
    with open(pids, "w") as fh:
        fh.write("".join(f"{k}\n" for k in kids))
    for k in kids:
        os.waitpid(k, 0)


def _program(tmp_path) -> tuple[str, str]:
    """A program whose lattice() forks ``workers`` holding 150 MiB each for ``seconds`` (with forks=0, it
    ``hold``s 150 MiB itself)."""
    pids = tmp_path / "pids.txt"
    prog = tmp_path / "prog.py"
    prog.write_text(f"""import os, time
from ple.model.lattice import Lattice

MIB = {MIB}


{inspect.getsource(hold)}

{inspect.getsource(workers)}

def lattice(forks=3, seconds=0.5):
    if forks:
        workers(forks, 150, seconds, {str(pids)!r})
    else:
        hold(150, 0)
    lat = Lattice()
    lat.add_node([0, 0, 0], 0.1)
    return lat
""")
    return str(prog), str(pids)


def _children(pids: str) -> list[int]:
    with open(pids) as fh:
        return [int(x) for x in fh.read().split()]


def test_a_tree_past_the_limit_is_stopped_whole(tmp_path):
    prog, pids = _program(tmp_path)
    run = ple("info", prog, "--max-memory", "300M", "--param", f"seconds={HOLD}")
    assert_clean_failure(run, "prog.py: the program ran out of memory: its 4 processes together held",
                         "(limit 300 MiB); raise it with --max-memory")
    kids = _children(pids)
    assert len(kids) == 3 and all(gone(k) for k in kids), kids


def test_a_tree_within_the_limit_runs_to_its_end(tmp_path):
    prog, pids = _program(tmp_path)
    run = ple("info", prog, "--max-memory", "2G")
    assert run.returncode == 0 and "1 x 1 x 1" in run.stdout, run.stderr
    assert len(_children(pids)) == 3


def test_one_process_within_the_limit_is_not_stopped(tmp_path):
    prog, _ = _program(tmp_path)
    run = ple("info", prog, "--max-memory", "300M", "--param", "forks=0")
    assert run.returncode == 0 and "1 x 1 x 1" in run.stdout, run.stderr


def test_a_job_stops_a_tree_past_the_limit_and_names_it(tmp_path):
    pids = str(tmp_path / "pids.txt")
    job = Job(lambda: workers(3, 150, HOLD, pids), "w.py", HOLD, 300 * MIB, "the work", Hints(memory="ask for more"))
    with pytest.raises(PleError, match=r"^w\.py: the work ran out of memory: its 4 processes together held "
                                       r"[0-9.]+ MiB \(limit 300 MiB\); ask for more$"):
        job.result()
    with pytest.raises(PleError, match="ran out of memory"):  # the error stays, as a time limit's does
        job.poll()
    assert all(gone(k) for k in _children(pids))


def _shared_then(pids: str, forks: int):
    """Work that touches 200 MiB, forks three children that only read it for a second, then
    ``forks`` children that each hold 150 MiB more for a second."""
    def work():
        block = bytearray(200 * MIB)
        for i in range(0, len(block), 4096):
            block[i] = 1
        workers(3, 0, 1.0, pids)
        workers(forks, 150, 1.0, pids)
        return len(block)
    return work


def test_pages_a_fork_shares_count_once(tmp_path, monkeypatch):
    """The forks' resident sets count the 200 MiB they share each: the sum passes 400 MiB
    (stopped when only resident sets are counted), what the tree holds (PSS) does not."""
    work = _shared_then(str(tmp_path / "pids.txt"), 0)
    assert Job(work, "w.py", HOLD, 400 * MIB).result() == 200 * MIB
    monkeypatch.setattr(proctree, "HAS_PSS", False)
    with pytest.raises(PleError, match="ran out of memory: its [234] processes together held"):
        Job(work, "w.py", HOLD, 400 * MIB).result()


def test_what_ended_forks_shared_hides_nothing_later(tmp_path):
    """The three readers end; then two forks hold 150 MiB each: 200 + 300 MiB pass 400, although
    the resident sets, less what the readers shared, stay below it."""
    pids = str(tmp_path / "pids.txt")
    with pytest.raises(PleError, match="ran out of memory: its 3 processes together held"):
        Job(_shared_then(pids, 2), "w.py", HOLD, 400 * MIB).result()
    assert all(gone(k) for k in _children(pids))


def test_without_proc_each_process_keeps_its_own_limit(monkeypatch):
    """Where /proc is missing (macOS) the tree is not watched; the address-space limit of each
    process still stops one allocation past it."""
    monkeypatch.setattr(proctree, "TREE_MEMORY", False)
    job = Job(lambda: bytearray(20 << 30), "bomb", HOLD, 1 << 30, "the bomb")
    assert job._memory is None
    with pytest.raises(PleError, match=r"bomb: the bomb ran out of memory \(limit 1 GiB\)"):
        job.result()
