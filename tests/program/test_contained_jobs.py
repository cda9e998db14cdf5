"""ple.program.runner.Job (the contained work of the add-on's jobs) and Lattice.evaluate_steps (a
filter asked box by box): what the work yields comes back in order, its result equals the same work
done in-process, a time limit stops even one long builtin call, cancel kills the child at once, and
program text run contained gives its inputs."""

from __future__ import annotations

import os

import numpy as np
import pytest
from ple.errors import PleError
from ple.program.runner import Hints, Job, run_text
from ple.program.sources import load_lattice


def gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def drain(gen):
    fracs = []
    while True:
        try:
            fracs.append(next(gen))
        except StopIteration as stop:
            return fracs, stop.value


@pytest.mark.parametrize("preset", ["hier_lil2", "hier_stencil", "hier_gyroid", "cubic"])
@pytest.mark.parametrize("boxes", [1, 5, 1000])
def test_evaluate_steps_is_evaluate(preset, boxes):
    lat = load_lattice(preset)
    r = lat.region("1:5,0:3,0:4") if min(lat.counts) >= 5 else lat.region()
    fracs, ev = drain(lat.evaluate_steps(r, max_groups=boxes))
    want = lat.evaluate(r)
    for key, value in want.arrays().items():
        assert np.array_equal(getattr(ev, key), value), key
    if lat.filter is not None:  # asked box by box: the fractions rise to 1
        assert fracs == sorted(fracs) and fracs[-1] == 1.0 and len(fracs) == len(list(lat.iter_slabs(boxes, r)))


def test_job_streams_items_and_returns_the_result():
    lat = load_lattice("hier_lil2")
    r = lat.region("0:4,0:3,0:3")
    job = Job(lambda: lat.evaluate_steps(r, max_groups=4), "hier_lil2", 60, None, "the filter")
    ev = job.result()
    fracs = job.take()
    assert fracs == drain(lat.evaluate_steps(r, max_groups=4))[0]  # every message, in order
    assert np.array_equal(ev.beam_nodes, lat.evaluate(r).beam_nodes) and job.take() == []


def test_time_limit_stops_one_long_builtin_call():
    job = Job(lambda: sum(range(10**13)), "sum.py", 0.3, None, "the sum", Hints(timeout="wait less"))
    with pytest.raises(PleError, match=r"sum.py: the sum ran longer than 0.3 s; wait less"):
        job.result()
    assert job.done  # the sum alone would take hours: returning at all is the child killed


def test_cancel_kills_the_child_at_once():
    job = Job(lambda: sum(range(10**13)), "sum.py", None, None, "the sum")
    pid = job._pid
    assert not job.poll(0.05) and not gone(pid)
    job.cancel()
    assert gone(pid) and job.done


def test_memory_limit_and_errors_name_the_work():
    job = Job(lambda: bytearray(20 * 2**30), "bomb", None, 2**30, "the bomb", Hints(memory="ask for more"))
    with pytest.raises(PleError, match=r"bomb: the bomb ran out of memory \(limit 1 GiB\); ask for more"):
        job.result()
    with pytest.raises(PleError, match="x: bad raised ValueError: no"):
        Job(lambda: (_ for _ in ()).throw(ValueError("no")), "x", 10, None, "the bad").result()


def test_run_text_gives_the_lattice_and_its_inputs():
    text = ("def lattice(n: Range(2, 9) = 3, r=0.1):\n    lat = Lattice()\n    lat.add_node(Pt(0, 0, 0), r)\n"
            "    lat.set_u(n, Translation(Vec(1, 0, 0)))\n    return lat\n")
    lat, inputs = run_text(text, "t.py", {"n": 5})
    assert lat.counts == (5, 1, 1) and lat.nodes[0].radius == 0.1
    assert [(p.name, p.default) for p in inputs] == [("n", 3), ("r", 0.1)]
    assert (inputs[0].range.lo, inputs[0].range.hi) == (2, 9) and inputs[1].range is None
    with pytest.raises(PleError, match="t.py: the program ran longer than 0.3 s"):
        run_text("while True:\n    pass\n", "t.py", None, timeout=0.3)


def test_without_fork_the_work_runs_in_process(monkeypatch):
    monkeypatch.delattr(os, "fork")  # as on Windows
    lat = load_lattice("hier_lil2")
    r = lat.region("0:4,0:3,0:3")
    job = Job(lambda: lat.evaluate_steps(r, max_groups=4), "hier_lil2", 60, None, "the filter")
    assert job.done and job.take() == drain(lat.evaluate_steps(r, max_groups=4))[0]
    assert np.array_equal(job.result().beam_nodes, lat.evaluate(r).beam_nodes)


def test_a_process_the_work_forks_ends_without_unwinding_the_work(tmp_path):
    """multiprocessing ends a forked child with os._exit; in a job that must exit the child, not
    unwind the stack it inherited (whose ``finally`` blocks, such as an atomic write's, would
    remove the job's temporary file: an export whose local union ran in a child lost its file)."""
    import multiprocessing

    from ple.io.files import atomic_path

    out = tmp_path / "out.txt"

    def work():
        with atomic_path(out) as tmp:
            tmp.write_text("written")
            child = multiprocessing.get_context("fork").Process(target=int)
            child.start()
            child.join()
        return child.exitcode

    assert Job(work, "forks", 30.0).result() == 0
    assert out.read_text() == "written"
    assert not [p for p in tmp_path.iterdir() if p.name != "out.txt"]  # no temporary left
