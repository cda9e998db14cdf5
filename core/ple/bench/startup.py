"""Start-up of the ``ple`` command: ``ple presets`` and ``ple --help`` timed as whole processes,
10 runs each (median, min, max), beside a bare ``python -c pass`` (the interpreter's own
start-up, the floor) and ``python -c "import numpy"`` in the same run. Issue 14 asks for a
median of at most 0.3 s: heavy modules (trimesh, scipy, the benchmarks, the program runtime)
are imported only by the sub-command that needs them."""

from __future__ import annotations

import statistics
import subprocess
import sys
import time

from ..errors import PleError

COMMANDS = {
    "ple presets": ["-m", "ple.cli", "presets"],
    "ple --help": ["-m", "ple.cli", "--help"],
    "baseline python -c pass": ["-c", "pass"],
    "baseline python -c 'import numpy'": ["-c", "import numpy"],
}


def add_arguments(p) -> None:
    p.add_argument("--runs", type=int, default=10, help="runs per command (default 10)")


def _times(argv: list[str], runs: int) -> list[float]:
    out = []
    for _ in range(runs + 1):  # the first run warms the file cache and is not counted
        t0 = time.perf_counter()
        subprocess.run([sys.executable, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        out.append(time.perf_counter() - t0)
    return out[1:]


def startup_rows(runs: int = 10) -> dict:
    """Median, min and max wall seconds of each command; runs interleaved (a burst of load hits all)."""
    times: dict = {name: [] for name in COMMANDS}
    for _ in range(runs):
        for name, argv in COMMANDS.items():
            times[name] += _times(argv, 1)
    return {name: {"median_s": round(statistics.median(t), 4), "min_s": round(min(t), 4), "max_s": round(max(t), 4),
                   "runs": len(t)} for name, t in times.items()}


def run(args) -> dict:
    if not 1 <= args.runs <= 100:
        raise PleError(f"--runs {args.runs}: expected 1..100")
    rows = startup_rows(args.runs)
    return {"benchmark": "startup", "target_median_s": 0.3, "commands": rows,
            "ple_presets_within_target": rows["ple presets"]["median_s"] <= 0.3}
