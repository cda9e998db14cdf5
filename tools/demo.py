"""``make demo``: a preset through the whole pipeline — program → LiL filter → refined
tessellation → binary STL and 3MF beam lattice → rendered PNG — with a printed summary
(counts, volume, times, file sizes) and the output paths."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ple.io.export import export_mesh, write_beam_lattice_3mf
from ple.io.irfile import save_ir
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

from tools.render import render as render_png

DEFAULT_PRESET = "hier_lil2"
DEFAULT_PARAMS = {"n": 13, "coarse_cells": 2, "fine_radius": 0.07, "coarse_radius": 0.7}
DEFAULT_LEVELS = 3


class _Clock:
    def __init__(self) -> None:
        self.times: dict[str, float] = {}

    def __call__(self, name: str, fn, *args, **kwargs):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.times[name] = time.perf_counter() - t0
        return out


def run(out_dir: Path, preset: str, params: dict, levels: int | None, render: bool) -> dict:

    out_dir.mkdir(parents=True, exist_ok=True)
    clock = _Clock()
    lat = clock("program", load_lattice, preset, params)
    save_ir(lat, out_dir / f"{preset}.json")
    kept = clock("LiL filter" if lat.filter is not None else "evaluate", lat.evaluate)
    kwargs = {"levels": levels} if levels is not None else {}
    mesh = clock("refined tessellation", tessellate, lat, style="refined", **kwargs)
    stl = out_dir / f"{preset}.stl"
    clock("binary STL", export_mesh, mesh, stl)
    beam3mf = out_dir / f"{preset}_beams.3mf"
    clock("3MF beam lattice", write_beam_lattice_3mf, beam3mf, kept.center, kept.radius, kept.beam_nodes)
    outputs = {"fine lattice (IR)": out_dir / f"{preset}.json", "watertight mesh (STL)": stl,
               "beam lattice (3MF)": beam3mf}
    if render:
        png = out_dir / f"{preset}.png"
        clock("render", render_png, png, [mesh], size="800x600")
        outputs["picture"] = png
    return {"lattice": lat, "kept": kept, "mesh": mesh, "times": clock.times, "outputs": outputs}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tools.demo", description=__doc__)
    ap.add_argument("--out", default="out/demo")
    ap.add_argument("--preset", default=DEFAULT_PRESET)
    ap.add_argument("--levels", type=int)
    ap.add_argument("--no-render", action="store_true")
    args = ap.parse_args(argv)
    params = DEFAULT_PARAMS if args.preset == DEFAULT_PRESET else {}
    t0 = time.perf_counter()
    levels = args.levels if args.levels is not None else DEFAULT_LEVELS
    res = run(Path(args.out), args.preset, params, levels, not args.no_render)
    lat, kept, mesh = res["lattice"], res["kept"], res["mesh"]
    nu, nv, nw = lat.counts
    print(f"\nPLE demo — preset {args.preset!r} {params or ''}")
    print(f"  program     {nu}x{nv}x{nw} groups, {lat.node_count():,} balls, {lat.beam_count():,} beams")
    print(f"  LiL filter  kept {len(kept.center):,} balls and {len(kept.beam_nodes):,} beams")
    print(f"  mesh        {len(mesh.faces):,} triangles, watertight={mesh.is_watertight}, "
          f"winding consistent={mesh.is_winding_consistent}, volume {mesh.volume:.6g}")
    print("  times       " + ", ".join(f"{k} {v:.2f} s" for k, v in res["times"].items()))
    print(f"  total       {time.perf_counter() - t0:.1f} s")
    print("  outputs:")
    for what, path in res["outputs"].items():
        print(f"    {what:<22} {path}  ({path.stat().st_size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
