"""CLG (thesis §5.5–5.7): PMC of 10⁵ points on a 100×100 BeCOTS CLG against the brute-force CSG tree
(every chunk copy) in the same run, and with the box bound alone against the conical shell;
voxelization; a progressive 640×480 render; the memory peak of
slicing a 10⁸-beam plain lattice (a few layers, streamed)."""

from __future__ import annotations

import json
import os
import time
import tracemalloc

import numpy as np

from ..clg.grid import iter_slices, voxelize, voxelize_clg
from ..clg.ir import clg_from_dict
from ..clg.query import Compiled, brute_force_value, compiled
from ..clg.rays import render
from ..program.clg_sources import resolve_clg
from ..program.sources import load_lattice
from ..queries.biq import pmc as lattice_pmc


def add_arguments(p) -> None:
    p.add_argument("--counts", default="100,100", help="BeCOTS counts of the PMC CLG (the plate preset)")
    p.add_argument("--points", type=int, default=100_000)
    p.add_argument("--brute-points", type=int, default=200, help="points timed by brute force (per-point rate)")
    p.add_argument("--voxels", type=int, default=256, help="voxel grid N (N³) of the shelled preset")
    p.add_argument("--voxel-check", type=int, default=8, help="x-slabs voxelized by per-voxel PMC (baseline)")
    p.add_argument("--render-size", default="640,480")
    p.add_argument("--slice-n", type=int, default=322, help="cubic lattice n (3 n²(n−1) beams ≈ 10⁸ at 322)")
    p.add_argument("--slice-layers", type=int, default=2)
    p.add_argument("--seed", type=int, default=7)


def _plate(counts):
    """The plate preset (10×10 cells) with other counts: its template shrinks with the cells."""
    data = json.loads(resolve_clg("plate").read_text())
    data["pattern"]["becots"]["counts"] = list(counts)
    k = 10 / max(counts)
    for node in data["pattern"]["nodes"]:
        node["center"] = [x * k for x in node["center"]]
        node["radius"] *= k
    return clg_from_dict(data)


def run(args) -> dict:
    out = {"benchmark": "clg", "cpus": os.cpu_count()}
    counts = [int(x) for x in args.counts.split(",")]
    clg = _plate(counts)
    t0 = time.perf_counter()
    comp = compiled(clg)
    prep = time.perf_counter() - t0
    rng = np.random.default_rng(args.seed)
    pts = comp.lo + rng.random((args.points, 3)) * (comp.hi - comp.lo)
    comp.pmc(pts[:1000])  # warm the RangeFinder plan
    t0 = time.perf_counter()
    inside = comp.pmc(pts)
    fast = time.perf_counter() - t0
    m = min(args.brute_points, args.points)
    t0 = time.perf_counter()
    brute = brute_force_value(clg, pts[:m]) <= 0
    slow = (time.perf_counter() - t0) / m * args.points
    out["pmc"] = {"clg": "plate preset, template scaled to the cells", "counts": counts,
                  "chunk_copies": clg.pattern.groups * 2,
                  "points": args.points, "inside": int(inside.sum()), "prepare_s": prep, "clg_pmc_s": fast,
                  "brute_force_s_extrapolated": slow, "brute_force_timed_points": m,
                  "speedup": slow / fast, "agree_on_timed_points": bool(np.array_equal(brute, inside[:m]))}
    box_only = Compiled(clg, shell=False)  # the bound before the conical shell: the box alone
    box_only.pmc(pts[:1000])
    t0 = time.perf_counter()
    inside_box = box_only.pmc(pts)
    boxed = time.perf_counter() - t0
    zero = np.zeros(len(pts))
    out["bound"] = {"clg": out["pmc"]["clg"], "points": args.points, "box_only_pmc_s": boxed,
                    "conical_shell_pmc_s": fast, "speedup": boxed / fast,
                    "points_past_box": int(len(box_only.near(pts, zero))),
                    "points_past_shell": int(len(comp.near(pts, zero))),
                    "shell": None if comp.shell is None else {"phi": list(comp.shell.phi),
                                                              "dist": list(comp.shell.dist)},
                    "agree": bool(np.array_equal(inside_box, inside))}
    shelled = compiled(clg_from_dict(json.loads(resolve_clg("shelled").read_text())))
    n = args.voxels
    t0 = time.perf_counter()
    vox = voxelize_clg(shelled, shelled.lo, shelled.hi, (n, n, n))
    secs = time.perf_counter() - t0
    m = min(args.voxel_check, n)  # baseline: PMC per voxel centre on the first x-slabs, same run
    t0 = time.perf_counter()
    ref = voxelize(shelled.pmc, shelled.lo, shelled.hi, (n, n, n), slabs=m)
    per_slab = (time.perf_counter() - t0) / m
    out["voxelize"] = {"clg": "shelled preset", "grid": [n, n, n], "seconds": secs, "inside": int(vox.sum()),
                       "pmc_per_voxel_s_extrapolated": per_slab * n, "pmc_per_voxel_timed_slabs": m,
                       "agree_on_timed_slabs": bool(np.array_equal(ref, vox[:m]))}
    w, h = (int(x) for x in args.render_size.split(","))
    t0 = time.perf_counter()
    passes = []
    render(shelled, (w, h), on_pass=lambda k, img: passes.append(time.perf_counter() - t0))
    out["render"] = {"clg": "shelled preset", "size": [w, h], "seconds": time.perf_counter() - t0,
                     "pass_done_at_s": passes}
    lat = load_lattice("cubic", [f"n={args.slice_n}"])
    r = 0.1
    lo = np.array([-r, -r, args.slice_n / 2])
    hi = np.array([args.slice_n - 1 + r, args.slice_n - 1 + r, args.slice_n / 2 + args.slice_layers * 0.25])
    tracemalloc.start()
    t0 = time.perf_counter()
    filled = [int(mask.sum()) for _, _, mask in iter_slices(lambda p: lattice_pmc(lat, p), lo, hi, 0.25, 0.25)]
    secs = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    out["slice"] = {"lattice": f"cubic n={args.slice_n}", "beams": lat.beam_count(), "layers": len(filled),
                    "pixels_per_layer": int(((hi[0] - lo[0]) / 0.25 + 1) ** 2), "seconds": secs,
                    "python_peak_mib": peak / 2 ** 20, "filled_pixels": filled}
    return out
