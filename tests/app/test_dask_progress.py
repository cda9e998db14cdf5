"""Progress of jobs on Dask (issue 17): under a terminal, a job on the embedded cluster shows Dask's
own progress bar and the dashboard's address on stderr, while stdout carries only the result; the
``sync`` path keeps the project's bar. The bar follows a resumed job and failing parts, and stops
with the job (no listener left behind)."""

from __future__ import annotations

import json
import os
import re
import sys
import threading
import time
from pathlib import Path

from daskcluster import eventually, on_terminal
from ple.app.cluster import dask_client, run_job, run_tasks
from ple.app.jobs import mesh_job
from ple.errors import PleError

ROOT = Path(__file__).resolve().parents[2]
MESH = ["mesh", "cubic", "--param", "n=4", "--style", "cnt", "--box-groups", "8"]


def under_terminal(args: list[str]) -> tuple[int, str, str]:
    path = os.pathsep.join([str(ROOT / "core"), str(ROOT), os.environ.get("PYTHONPATH", "")])
    return on_terminal([sys.executable, "-m", "ple.cli", *args], dict(os.environ, PYTHONPATH=path), ROOT)


def _hashes(folder: Path) -> dict:
    return {n: e["sha256"] for n, e in json.loads((folder / "manifest.json").read_text())["parts"].items()}


def test_dask_bar_and_dashboard_on_a_terminal_stdout_clean(tmp_path):
    parts = tmp_path / "parts"
    code, out, err = under_terminal([*MESH, "--parts", str(parts), "--scheduler", "local", "--workers", "2"])
    assert code == 0, err[-2000:]
    assert re.search(r"dask dashboard: http://[\w.\-]+:\d+/status", err)
    assert "mesh [" in err and "| 100% Completed |" in err  # Dask's bar, drawn on stderr to its end
    assert "Warning" not in err and "Traceback" not in err and "Error" not in err  # a clean start and stop
    assert re.fullmatch(r"8 part\(s\) written, 0 already there, 0 failed \([\d.]+ s\); manifest \S+\n", out)
    job = mesh_job("cubic", ["n=4"], "cnt", box_groups=8)
    run_job(job, str(tmp_path / "sync"), "sync", progress=False)  # the single-process reference
    assert _hashes(parts) == _hashes(tmp_path / "sync")
    assert all((parts / n).read_bytes() == (tmp_path / "sync" / n).read_bytes() for n in _hashes(parts))
    # resumed: only the missing part is submitted (to one worker: it is one task), and the bar counts it alone
    (parts / job.parts[3].name).unlink()
    code, out, err = under_terminal([*MESH, "--parts", str(parts), "--scheduler", "local", "--workers", "1"])
    assert code == 0 and out.startswith("1 part(s) written, 7 already there, 0 failed")
    assert "| 100% Completed |" in err and _hashes(parts) == _hashes(tmp_path / "sync")
    # the in-process path keeps the project's bar: no Dask, no dashboard
    code, out, err = under_terminal([*MESH, "--parts", str(tmp_path / "p2"), "--scheduler", "sync"])
    assert code == 0 and "mesh [" in err and "100.0%" in err
    assert "Completed" not in err and "dashboard" not in err


def test_failing_variants_under_a_terminal(tmp_path):
    """A variant the program rejects is a result, not an erred task: the bar runs to the end and
    stdout is the JSON summary naming it."""
    code, out, err = under_terminal(["batch", "cubic", "--param", "n=0,2,3", "--style", "cnt", "--workers", "2",
                                     "--out", str(tmp_path / "b")])
    assert code == 2
    summary = json.loads(out)
    assert summary["written"] == 2 and [f["file"] for f in summary["failed"]] == ["cubic__n-0.stl"]
    assert "batch [" in err and "| 100% Completed |" in err and "dask dashboard:" in err
    assert "Warning" not in err and "Traceback" not in err


def slow_or_broken(i: int) -> int:
    """A task for the bar's test: part 1 raises a bug (an erred task, retried, then reported),
    part 2 a PleError (a result), the others take a little time."""
    if i == 1:
        raise ZeroDivisionError("a bug in part 1")
    if i == 2:
        raise PleError("part 2 is bad input")
    time.sleep(0.4)
    return i


def test_the_bar_outlives_an_erred_task_and_stops_with_the_job(capsys):
    before = set(threading.enumerate())
    with dask_client("local", 1) as client:
        got = dict(run_tasks(client, slow_or_broken, [(i,) for i in range(8)], list(range(8)), "parts",
                             progress=True))
        assert isinstance(got[1], ZeroDivisionError) and isinstance(got[2], PleError)
        assert {i: got[i] for i in (0, *range(3, 8))} == {i: i for i in (0, *range(3, 8))}
        bars = [line for line in capsys.readouterr().err.split("\n") if "Completed" in line]
        # the erred part stopped Dask's first bar early; a second one took over the pending parts
        assert len(bars) >= 2 and "100% Completed" not in bars[0]
        assert bars[-1].split("\r")[-1].startswith("parts [") and "| 100% Completed |" in bars[-1]
        tasks = run_tasks(client, slow_or_broken, [(i,) for i in range(10, 20)], list(range(10, 20)), "cut",
                          progress=True)
        next(tasks)
        tasks.close()  # an interrupted job: its bar stops (on the client's loop) and ends its line
        err: list[str] = []
        assert eventually(lambda: err.append(capsys.readouterr().err) or "".join(err).endswith("\n")), err
    assert eventually(lambda: {t.name for t in set(threading.enumerate()) - before} <= {"Dask-Offload_0"}), \
        {t.name for t in set(threading.enumerate()) - before}
