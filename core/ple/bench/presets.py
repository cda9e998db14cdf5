"""Every preset meshed with its defaults in every closed style, as a user runs it.

Each (preset, style) is ``ple mesh NAME --style STYLE --out F.stl`` in a fresh process with the
preset's own parameters: exit code, wall and CPU seconds, peak resident memory, triangles, the
unclean report and, for a refusal or a failure, the message's last line. A run longer than
``--timeout`` is stopped and reported as such (not as a success). The baseline in the same run
is ``ple info NAME`` (evaluation and the exact volume, no mesh), so a slow mesh can be told from
a slow program.
"""

from __future__ import annotations

import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time

from ..program.presets import preset_names

STYLES = ("refined", "cnt", "chocc")


def add_arguments(p) -> None:
    p.add_argument("--presets", default="all", help="comma-separated preset names, or all (default)")
    p.add_argument("--styles", default=",".join(STYLES), help="comma-separated styles (default: refined,cnt,chocc)")
    p.add_argument("--timeout", type=float, default=300.0, help="seconds after which a run is stopped (default 300)")


def _ple(args: list, timeout: float) -> dict:
    """One ``ple`` command in a fresh process: exit code, seconds, CPU seconds of the child, its
    peak resident memory (GB), and the last line of its output."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-m", "ple.cli", *args], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"timeout": timeout}
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    lines = (proc.stdout + proc.stderr).strip().splitlines()
    return {"exit": proc.returncode, "seconds": round(time.perf_counter() - t0, 3),
            "cpu_seconds": round(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, 3),
            # ru_maxrss of children is the largest child so far: reported as an upper bound
            "peak_rss_gb_at_most": round(after.ru_maxrss / 1e6, 3), "last": lines[-1] if lines else "",
            "output": lines}


def run(args) -> dict:
    names = preset_names() if args.presets == "all" else args.presets.split(",")
    styles = args.styles.split(",")
    rows = []
    with tempfile.TemporaryDirectory(prefix="ple-bench-presets-") as d:
        out = os.path.join(d, "m.stl")
        for name in names:
            info = _ple(["info", name], args.timeout)
            for style in styles:
                got = _ple(["mesh", name, "--style", style, "--out", out], args.timeout)
                row = {"preset": name, "style": style, "info_seconds": info.get("seconds"), **got}
                lines = row.pop("output", [])
                row["unclean"] = next((x for x in lines if "unclean lattice" in x), None)
                tris = [re.search(r"^wrote .*: ([\d,]+) triangles", x) for x in lines]
                row["triangles"] = next((int(t.group(1).replace(",", "")) for t in tris if t), None)
                row["note"] = next((x for x in lines if x.startswith("note:")), None)  # e.g. fewer levels
                row["meshed"] = got.get("exit") == 0
                if os.path.exists(out):
                    os.unlink(out)
                rows.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
    return {"bench": "presets", "rows": rows,
            "all_meshed": all(r["meshed"] for r in rows),
            "failed": [f"{r['preset']} {r['style']}: {r.get('last') or 'timeout'}" for r in rows if not r["meshed"]]}
