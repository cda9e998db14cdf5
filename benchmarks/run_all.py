"""Run every ``ple bench`` benchmark, keep its JSON in benchmarks/results/, then write
docs/performance.md (tables beside the thesis numbers) and its plot.

Usage: .venv/bin/python benchmarks/run_all.py [NAME …]   (default: all benchmarks)
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
PLE = Path(sys.executable).parent / "ple"


def bench_names() -> list[str]:
    import pkgutil

    from ple import bench
    return [m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_")]


def main(argv: list[str]) -> int:
    RESULTS.mkdir(exist_ok=True)
    names = argv or bench_names()
    for name in names:
        t0 = time.perf_counter()
        print(f"ple bench {name} …", flush=True)
        proc = subprocess.run([str(PLE), "bench", name, "--out", str(RESULTS / f"{name}.json")],
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if proc.returncode != 0:
            print(f"  failed: {proc.stderr.strip()[-600:]}", file=sys.stderr)
            return 1
        print(f"  {time.perf_counter() - t0:.1f} s -> {RESULTS / f'{name}.json'}")
    meta = {"machine": platform.platform(), "python": platform.python_version(), "cores": _cores(),
            "date": time.strftime("%Y-%m-%d")}
    (RESULTS / "machine.json").write_text(json.dumps(meta, indent=1) + "\n")
    from report import write_report
    write_report()
    return 0


def _cores() -> int:
    import os
    return os.cpu_count() or 1


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    sys.exit(main(sys.argv[1:]))
