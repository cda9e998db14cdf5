"""Partitioned and distributed jobs run their programs contained, under the command's limits
(docs/reliability.md, *Contained programs*): where a job is planned (``mesh_job``, ``filter_job``,
``count_job``, ``slice_job``, ``ple batch``'s plan) and where its parts are computed
(``job_lattice``, ``_sweep_part``), in this process (``--scheduler sync``) and on Dask workers.

A program that loops forever at one door is stopped at ``--timeout`` with exit 2 and the
message the command gives without parts; a program that forks a grandchild which sleeps leaves
no process behind. The program counts its runs in a file, so each test knows which run crosses
which door; the grandchildren write their pids to a file and must be gone (psutil) once the
command has ended."""

from __future__ import annotations

import pytest
from ple.app.batch import plan
from ple.app.cluster import run_job
from ple.app.jobs import slice_job, sweep_job
from ple.cli.main import main
from ple.errors import PleError
from reliability_helpers import gone

TIMEOUT = 1.5  # seconds: the limit of every run here (a run that behaves takes milliseconds)
SLEEP = 120  # seconds a grandchild sleeps: far beyond any run here
STOPPED = f"the program ran longer than {TIMEOUT:g} s; raise the limit with --timeout"

PROGRAM = """import os, time

RUNS, PIDS, HANG_AT, FORKS = {runs!r}, {pids!r}, {hang_at!r}, {forks!r}


def lines(path):
    return open(path).read().count("\\n") if os.path.exists(path) else 0


def sleeper():
    with open(PIDS, "a") as fh:
        fh.write(f"{{os.getpid()}}\\n")
    time.sleep({sleep})
    os._exit(0)


def lattice(n: Range(1, 10) = 3):
    with open(RUNS, "a") as fh:
        fh.write("run\\n")
    run = lines(RUNS)
    if FORKS:  # a grandchild per run, started before the run returns
        if os.fork() == 0:
            sleeper()
        while lines(PIDS) < run:
            time.sleep(0.01)
    if HANG_AT is not None and run >= HANG_AT:
        while True:
            pass
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.1)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    return lat
"""

# each door's command (PROG and PARTS filled in) and its runs of the program: the command's own
# lattice (filter, slice), the job's plan (mesh, filter, count) and the parts (one run: the cache)
COMMANDS = {
    "mesh": (["mesh", "PROG", "--style", "cnt", "--box-groups", "9"], {"plan": 1, "parts": 2}),
    "filter": (["filter", "PROG", "--stencil", "checker:2", "--slab-groups", "9"], {"plan": 2, "parts": 3}),
    "count": (["filter", "PROG", "--stencil", "checker:2", "--slab-groups", "9", "--count"], {"plan": 2, "parts": 3}),
    "slice": (["slice", "PROG", "--layer", "0.5", "--pixel", "0.1", "--layers-per-part", "2"], {"parts": 2}),
}


def _program(tmp_path, hang_at: int | None = None, forks: bool = False) -> tuple[str, str, str]:
    """(program, its runs file, its grandchildren's pids file)."""
    runs, pids = str(tmp_path / "runs.txt"), str(tmp_path / "pids.txt")
    prog = tmp_path / "prog.py"
    prog.write_text(PROGRAM.format(runs=runs, pids=pids, hang_at=hang_at, forks=forks, sleep=SLEEP))
    return str(prog), runs, pids


def _count(path: str) -> int:
    try:
        with open(path) as fh:
            return fh.read().count("\n")
    except FileNotFoundError:
        return 0


def _sleepers(pids: str) -> list[int]:
    with open(pids) as fh:
        return [int(x) for x in fh.read().split()]


def _command(name: str, prog: str, parts, scheduler: list[str]) -> list[str]:
    args, _ = COMMANDS[name]
    return [prog if a == "PROG" else a for a in args] + ["--parts", str(parts), *scheduler,
                                                           "--timeout", f"{TIMEOUT:g}"]


@pytest.mark.parametrize("name, door", [(n, d) for n, (_, runs) in COMMANDS.items() for d in runs])
def test_a_program_looping_at_a_door_of_a_job_is_stopped_by_timeout(tmp_path, capsys, name, door):
    at = COMMANDS[name][1][door]
    prog, runs, _ = _program(tmp_path, hang_at=at)
    assert main(_command(name, prog, tmp_path / "parts", ["--scheduler", "sync"])) == 2
    err = capsys.readouterr().err
    assert f"{prog}: {STOPPED}" in err and "Traceback" not in err, err
    if door == "parts":  # every part failed, named, with the command's message; the program ran once
        failed = [x for x in err.splitlines() if x]
        assert len(failed) > 1 and all(x.startswith("failed part_") and x.endswith(STOPPED) for x in failed), err
    assert _count(runs) == at  # nothing ran the program after it was stopped


@pytest.mark.parametrize("name", COMMANDS)
def test_no_grandchild_of_a_job_s_program_outlives_the_command(tmp_path, capsys, name):
    prog, runs, pids = _program(tmp_path, forks=True)
    assert main(_command(name, prog, tmp_path / "parts", ["--scheduler", "sync"])) == 0, capsys.readouterr().err
    assert _count(runs) == max(COMMANDS[name][1].values())  # every door ran the program
    sleepers = _sleepers(pids)
    assert len(sleepers) == _count(runs) and all(gone(p) for p in sleepers), sleepers


@pytest.mark.parametrize("forks", [False, True])
def test_dask_workers_run_the_program_contained_with_the_limits(tmp_path, capsys, forks):
    """The embedded Dask cluster: the limits reach the worker, and its program's tree ends."""
    prog, runs, pids = _program(tmp_path, hang_at=None if forks else 2, forks=forks)
    code = main(_command("mesh", prog, tmp_path / "parts", ["--workers", "1"]))
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    if forks:
        assert code == 0 and _count(runs) == 2, err
        sleepers = _sleepers(pids)
        assert len(sleepers) == 2 and all(gone(p) for p in sleepers), sleepers
    else:
        failed = [x for x in err.splitlines() if x.startswith("failed part_")]
        assert code == 2 and len(failed) == 3 and all(x.endswith(f"{prog}: {STOPPED}") for x in failed), err


def test_slice_job_plans_its_bounds_contained(tmp_path):
    prog, _, _ = _program(tmp_path, hang_at=1)
    with pytest.raises(PleError, match=STOPPED):
        slice_job(prog, [], 0.5, 0.1, limits=(TIMEOUT, None))
    (tmp_path / "forks").mkdir()
    prog, runs, pids = _program(tmp_path / "forks", forks=True)
    job = slice_job(prog, [], 0.5, 0.1, layers_per_part=2, limits=(TIMEOUT, None))
    assert run_job(job, str(tmp_path / "parts"), "sync", progress=False)["written"] == len(job.parts)
    sleepers = _sleepers(pids)
    assert len(sleepers) == _count(runs) == 2 and all(gone(p) for p in sleepers), sleepers


def test_sweep_parts_run_the_program_contained(tmp_path):
    prog, runs, _ = _program(tmp_path, hang_at=1)
    _, variants = plan(prog, ["n=2,3"], "stl", (TIMEOUT, None))
    res = run_job(sweep_job(prog, variants, "cnt", "stl", limits=(TIMEOUT, None)), str(tmp_path / "hang"), "sync",
                  progress=False)
    assert sorted(res["failed"]) == sorted(v.filename for v in variants)
    assert all(f["error"] == f"{prog}: {STOPPED}" for f in res["failed"].values())
    (tmp_path / "forks").mkdir()
    prog, runs, pids = _program(tmp_path / "forks", forks=True)
    _, variants = plan(prog, ["n=2,3"], "stl")
    res = run_job(sweep_job(prog, variants, "cnt", "stl"), str(tmp_path / "forks" / "parts"), "sync", progress=False)
    assert res["written"] == 2 and not res["failed"]
    sleepers = _sleepers(pids)
    assert len(sleepers) == _count(runs) == 2 and all(gone(p) for p in sleepers), sleepers


def test_batch_plans_its_sweep_contained(tmp_path, capsys):
    """``ple batch`` reads the program's inputs by running its module's top level: contained too."""
    prog = tmp_path / "top.py"
    prog.write_text("while True:\n    pass\n\n\ndef lattice(n: Range(1, 3) = 2):\n    return Lattice()\n")
    assert main(["batch", str(prog), "--param", "n=1,2", "--style", "cnt", "--out", str(tmp_path / "out"),
                 "--scheduler", "sync", "--timeout", f"{TIMEOUT:g}"]) == 2
    err = capsys.readouterr().err
    assert f"{prog}: {STOPPED}" in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()
