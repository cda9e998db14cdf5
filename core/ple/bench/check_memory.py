"""Memory of the unclean check on the thesis' big lattices (issue 38, item 3): ``ple mesh``'s check
of the whole lattice (``Tessellator.find_unclean``) at a style, each in a fresh process, its peak
resident memory beside the check's estimate (``check_bytes``) and beside today's check (the core
at ``--baseline-rev``) in the same run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from ..errors import PleError
from ._timing import checkout

ROOT = Path(__file__).resolve().parents[3]
BASELINE_REV = "68b3830"  # before the check was made in blocks (its grid, boxes and neighbourhoods)
LATTICES = "thesis_regular,thesis_cylindrical,thesis_warped"

CHILD = """
import json, resource, sys, time
from ple.program.sources import load_lattice
from ple.meshing import tessellate as T
name, style = sys.argv[1], sys.argv[2]
lat = load_lattice(name)
levels, segments = T.resolve_style(style, None, None)
hubs, r = lat.per_hub(None)
t0, c0 = time.perf_counter(), time.process_time()
report, _ = T.Tessellator(hubs, r, style, levels, segments, None).find_unclean()
print("@@" + json.dumps({"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
                         "unclean_hubs": int(len(report.nodes)), "estimate_bytes": T.check_bytes(lat),
                         "elements": int(T.region_nodes(lat, r) + T.region_beams(lat, r)),
                         "peak_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def add_arguments(p) -> None:
    p.add_argument("--lattices", default=LATTICES, help="presets, comma-separated")
    p.add_argument("--style", default="cnt", choices=("refined", "cnt", "chocc"))
    p.add_argument("--baseline-rev", default=BASELINE_REV, help="the git revision whose check is the baseline")


def _check(core: Path, name: str, style: str) -> dict:
    res = subprocess.run([sys.executable, "-c", CHILD, name, style], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(core)}, cwd=tempfile.gettempdir())
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("@@")]
    if res.returncode != 0 or not lines:
        raise PleError(f"the check of {name} ({core}) failed: {res.stderr.strip()[-800:]}")
    return json.loads(lines[-1][2:])


def run(args) -> dict:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        checkout(args.baseline_rev, Path(tmp), "core")
        for name in args.lattices.split(","):
            ours = _check(ROOT / "core", name, args.style)
            base = _check(Path(tmp) / "core", name, args.style)
            if ours["unclean_hubs"] != base["unclean_hubs"]:
                raise PleError(f"{name}: the two checks find {ours['unclean_hubs']} and {base['unclean_hubs']} "
                               "unclean hubs")
            rows.append({"lattice": name, "style": args.style, "elements": ours["elements"],
                         "unclean_hubs": ours["unclean_hubs"], "seconds": round(ours["seconds"], 2),
                         "peak_gb": round(ours["peak_bytes"] / 1e9, 3),
                         "estimate_gb": round(ours["estimate_bytes"] / 1e9, 3),
                         "peak_over_estimate": (round(ours["peak_bytes"] / ours["estimate_bytes"], 3)
                                                if ours["estimate_bytes"] else None),
                         "checked_by_ple_mesh": ours["estimate_bytes"] > 0,  # beyond MAX_CHECK_GROUPS: not
                         "bytes_per_element": round(ours["peak_bytes"] / ours["elements"]),
                         "today_seconds": round(base["seconds"], 2),
                         "today_peak_gb": round(base["peak_bytes"] / 1e9, 3),
                         "under_2gb": ours["peak_bytes"] < 2e9})
    return {"benchmark": "check_memory", "baseline_rev": args.baseline_rev,
            "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg()[0]}, "rows": rows}
