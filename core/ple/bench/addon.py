"""Live editing in Blender at 10³ to 10⁶ drawn node-groups and on a 10⁹-node lattice (issue 39):
drag G, drag U, a count change, the first draw and the peak memory, each beside today's redraw
(the add-on and core at ``--baseline-rev``) in the same run, each case in a fresh process.

Needs the ``bpy`` module (the project's venv), the repository's ``ple_addon/`` and
``benchmarks/addon_redraw.py`` (the Blender side) beside the core, and ``git`` for the baseline."""

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
CHILD = ROOT / "benchmarks" / "addon_redraw.py"  # the Blender side, outside the core (no bpy here)
BASELINE_REV = "3cf9467"  # the last commit before issue 39: swept beams, every move redrawn in full
CASES = "100:10,100:30,100:50,100:100,1000:10"  # COUNT:REGION (a cubic lattice of COUNT³ groups, REGION³ drawn)
TARGETS_MS = {"drag_g_ms": 20, "drag_u_ms": 100}


def add_arguments(p) -> None:
    p.add_argument("--cases", default=CASES, help="COUNT:REGION, comma-separated (cubic COUNT³, REGION³ drawn)")
    p.add_argument("--edits", type=int, default=9, help="moves of each frame per case (their median is reported)")
    p.add_argument("--baseline-rev", default=BASELINE_REV, help="the git revision whose redraw is the baseline")


def _cases(text: str) -> list[tuple[int, int]]:
    out = []
    for item in text.split(","):
        try:
            count, region = (int(x) for x in item.split(":"))
        except ValueError:
            raise PleError(f"--cases {item!r}: expected COUNT:REGION (two whole numbers)") from None
        if not 1 <= region <= count:
            raise PleError(f"--cases {item!r}: the region must be 1 to COUNT groups")
        out.append((count, region))
    return out


def _blender(root: Path, count: int, region: int, edits: int) -> dict:
    res = subprocess.run([sys.executable, str(CHILD), str(root), str(count), str(region), str(edits)],
                         capture_output=True, text=True, cwd=tempfile.gettempdir(),
                         env={**os.environ, "PYTHONPATH": ""})
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("@@")]
    if res.returncode != 0 or not lines:
        raise PleError(f"the redraw of cubic {count}³ at {region}³ ({root}) failed: {res.stderr.strip()[-800:]}")
    return json.loads(lines[-1][2:])


def _rounded(d: dict) -> dict:
    return {k: round(v, 4) if isinstance(v, float) else v for k, v in d.items()}


def run(args) -> dict:
    cases = _cases(args.cases)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        today = checkout(args.baseline_rev, Path(tmp), "core", "ple_addon")
        for count, region in cases:
            ours = _blender(ROOT, count, region, args.edits)
            base = _blender(today, count, region, args.edits)
            if (ours["balls"], ours["beams"]) != (base["balls"], base["beams"]):
                raise PleError(f"cubic {count}³ at {region}³: the two redraws draw different regions")
            met = {k: ours[k] <= v for k, v in TARGETS_MS.items()}
            met["first_draw_1s"] = ours["first_draw_s"] <= 1.0
            met["peak_1gb"] = ours["peak_gb"] <= 1.0
            rows.append({"lattice_groups": count ** 3, "drawn_groups": region ** 3, "balls": ours["balls"],
                         "beams": ours["beams"], "ours": _rounded(ours), "today": _rounded(base),
                         "drag_u_speedup": round(base["drag_u_ms"] / ours["drag_u_ms"], 2),
                         "drag_g_speedup": round(base["drag_g_ms"] / ours["drag_g_ms"], 2), "targets_met": met})
    return {"benchmark": "addon", "baseline_rev": args.baseline_rev, "targets_ms": TARGETS_MS,
            "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg()[0]}, "rows": rows}
