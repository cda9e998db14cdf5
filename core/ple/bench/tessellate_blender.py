"""Tessellate of a big region in Blender (issue 37): the add-on's Tessellate beside ``ple mesh`` to
a file, in the same run, each in a fresh process: wall seconds and seconds per million
triangles, the peak memory of the process (the add-on's: Blender's own process; its child job
is apart) and, in the same Blender, today's path's baseline, the boxes sent to Blender and welded
there (the add-on's Tessellate until issue 37), which held every box twice.

Needs the ``bpy`` module (the project's venv) and the repository's ``ple_addon/`` and
``benchmarks/tessellate_blender_child.py`` (the Blender side) beside the core."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..errors import PleError

ROOT = Path(__file__).resolve().parents[3]
CASES = [("thesis_regular", "0:16,0:16,0:16", "cnt"), ("fig6_3", "0:7,0:12,0:15", "cnt"),
         ("cylindrical", "0:8,0:32,0:8", "chocc")]

CHILD = ROOT / "benchmarks" / "tessellate_blender_child.py"  # the Blender side, outside the core (no bpy here)


def add_arguments(p) -> None:
    p.add_argument("--cases", default=",".join(f"{a}:{b.replace(',', ';')}:{c}" for a, b, c in CASES),
                   help="PRESET:REGION:STYLE, comma-separated (REGION as I0:I1;J0:J1;K0:K1)")


def _parse(text: str) -> list[tuple[str, str, str]]:
    out = []
    for item in text.split(","):
        bits = item.split(":", 1)
        if len(bits) != 2 or bits[1].count(":") < 1:
            raise PleError(f"--cases {item!r}: expected PRESET:REGION:STYLE")
        preset, rest = bits
        region, style = rest.rsplit(":", 1)
        out.append((preset, region.replace(";", ","), style))
    return out


def _blender(preset: str, region: str, style: str, how: str) -> dict:
    res = subprocess.run([sys.executable, str(CHILD), str(ROOT), preset, region, style, how],
                         capture_output=True, text=True, cwd=tempfile.gettempdir())
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("@@")]
    if res.returncode != 0 or not lines:
        raise PleError(f"Blender's {how} tessellation of {preset} {region} failed: {res.stderr.strip()[-800:]}")
    return json.loads(lines[-1][2:])


def _ple_mesh(preset: str, region: str, style: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "m.stl"
        env = {**os.environ, "PYTHONPATH": str(ROOT / "core")}
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "ple.cli", "mesh", preset, "--region", region, "--style",
                                 style, "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                env=env, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        if os.waitstatus_to_exitcode(status) != 0:
            raise PleError(f"ple mesh {preset} failed: {proc.stderr.read()[-500:]}")
        triangles = (out.stat().st_size - 84) // 50
    return {"seconds": seconds, "triangles": int(triangles), "peak_bytes": usage.ru_maxrss * 1024}


def _row(d: dict) -> dict:
    out = {"seconds": round(d["seconds"], 3), "triangles": d["triangles"], "peak_gb": round(d["peak_bytes"] / 1e9, 3),
           "s_per_m_triangles": round(d["seconds"] / max(d["triangles"], 1) * 1e6, 3)}
    if "before_bytes" in d:
        out["peak_gain_gb"] = round((d["peak_bytes"] - d["before_bytes"]) / 1e9, 3)  # beyond the drawn rig
    return out


def run(args) -> dict:
    rows = []
    for preset, region, style in _parse(args.cases):
        addon = _blender(preset, region, style, "addon")
        base = _blender(preset, region, style, "baseline")
        cli = _ple_mesh(preset, region, style)
        if not addon["triangles"] == base["triangles"] == cli["triangles"]:
            raise PleError(f"{preset} {region}: the triangle counts differ ({addon['triangles']}, "
                           f"{base['triangles']}, {cli['triangles']})")
        rows.append({"preset": preset, "region": region, "style": style, "addon_tessellate": _row(addon),
                     "baseline_boxes_welded_in_blender": _row(base), "ple_mesh_to_file": _row(cli)})
    return {"benchmark": "tessellate_blender", "machine": {"cpus": os.cpu_count(), "load_average": os.getloadavg()[0]},
            "rows": rows}
