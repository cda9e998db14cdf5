"""CLG mesh budget: the estimate ``ple clg mesh`` is refused by (nested materials as meshed)
against the measured peak of the command and its child (PSS), on nested, template and copies cases."""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

from ..clg.ir import clg_from_dict
from ..clg.query import compiled
from ..errors import PleError, cut
from ..meshing.clg import estimated_triangles, solid_triangles
from ..model.budget import CLG_TRIANGLE_BYTES
from ..program.clg_sources import resolve_clg
from ._timing import peak_pss

LIMIT = 1.5  # the promise (docs/reliability.md): the peak stays within 1.5x the estimate


def add_arguments(p) -> None:
    p.add_argument("--segments", type=int, default=32, help="circle segments (default 32, the CLI's)")
    p.add_argument("--cases", default="", help="comma-separated case names to run (default: all)")


def _beam_of_beams(u: int, v: int, w: int = 1, truss: int | None = None) -> dict:
    """The beam-of-beams preset on u x v x w groups; ``truss``: cells of its nested material."""
    d = json.loads(resolve_clg("beam_of_beams").read_text())
    d["pattern"]["U"]["count"], d["pattern"]["V"]["count"] = u, v
    if w > 1:
        d["pattern"]["W"] = {"count": w, "similarity": {"kind": "translation", "vector": [0, 0, 2]}}
    if truss:
        t = d["materials"]["truss"]["replace"]["pattern"]
        t["U"] = {"count": truss, "similarity": {"kind": "translation", "vector": [1 / truss, 0, 0]}}
        t["placement"]["similarity"]["vector"] = [-1 / truss, 0, 0]
    return d


def _shelled(n: int) -> dict:
    d = json.loads(resolve_clg("shelled").read_text())
    for k in "UVW":
        d["pattern"][k]["count"] = n
    return d


def _balls(n: int, copies: int = 1) -> dict:
    """One chunk uniting ``n`` overlapping balls, on copies³ groups."""
    d = _shelled(copies)
    d["pattern"]["nodes"] = [{"id": f"a{i}", "center": [i * 0.05, (i % 7) * 0.1, (i % 5) * 0.1], "radius": 0.06}
                             for i in range(n)]
    d["pattern"]["beams"] = []
    d["chunks"] = {"X": {"union": [{"ball": {"node": [0, 0, 0, f"a{i}"], "scale": 1}} for i in range(n)]}}
    d["solid"] = "X"
    return d


CASES = {
    "beam_of_beams_3x3": lambda: _beam_of_beams(3, 3),
    "beam_of_beams_3x3x3": lambda: _beam_of_beams(3, 3, 3),
    "beam_of_beams_5x5x2": lambda: _beam_of_beams(5, 5, 2),
    "beam_of_beams_3x3_truss18": lambda: _beam_of_beams(3, 3, truss=18),
    "beam_of_beams_4x4x2_truss18": lambda: _beam_of_beams(4, 4, 2, truss=18),
    "shelled_6": lambda: _shelled(6),
    "shelled_10": lambda: _shelled(10),
    "balls_2000": lambda: _balls(2000),
    "balls_500_x8": lambda: _balls(500, 2),
}


def run(args) -> dict:
    names = [x for x in args.cases.split(",") if x] or list(CASES)
    unknown = [x for x in names if x not in CASES]
    if unknown:
        raise PleError(f"--cases: unknown {cut(', '.join(unknown))}; expected some of {', '.join(CASES)}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            doc = CASES[name]()
            comp = compiled(clg_from_dict(doc))
            tris = estimated_triangles(comp, args.segments)
            src = Path(tmp) / f"{name}.json"
            src.write_text(json.dumps(doc))
            got = peak_pss([sys.executable, "-m", "ple.cli", "clg", "mesh", str(src), "--segments", str(args.segments),
                            "--max-memory", "64G", "--out", str(Path(tmp) / f"{name}.stl")])
            est = tris * CLG_TRIANGLE_BYTES
            region = comp.region if comp.region is not None else comp.lat.region(None)
            rows.append({"case": name, "groups": region.groups,
                         "triangles_bound": solid_triangles(comp, args.segments), "triangles_estimate": tris,
                         "estimate_bytes": est, "peak_bytes": got["peak_bytes"], "peak_over_estimate":
                         got["peak_bytes"] / est, "seconds": got["seconds"], "exit": got["returncode"],
                         "result": (got["stdout"] or got["stderr"]).splitlines()[-1:]})
    return {"benchmark": "clg_budget", "cpus": os.cpu_count(), "load": os.getloadavg(), "segments": args.segments,
            "limit": LIMIT, "rows": rows, "worst": max(r["peak_over_estimate"] for r in rows),
            "within_limit": all(r["peak_over_estimate"] <= LIMIT for r in rows)}
