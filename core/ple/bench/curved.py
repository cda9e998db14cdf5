"""Curved lattices to binary STL: batched hub templates against the per-hub path (same run), 1 vs 2 workers.

The curved lattice of issue 14: translation U, rotation V (about z), swirl W, one ball and 4
beam-patterns — every (i, j) column has its own hub shape. Each row streams the region to a
binary STL (``iter_triangles`` + ``write_stl``, the cleanliness check left out) and reports
triangles per second; ``stl_writer_only`` writes the same triangles again from memory (the
ceiling of this machine). A regular (cubic) lattice of the same size is the reference."""

from __future__ import annotations

import os
import resource
import tempfile
import time

from ..algebra.similarity import Rotation, Swirl, Translation
from ..errors import PleError
from ..io.export import write_stl
from ..meshing.tessellate import _Tessellator, iter_triangles, output_grid
from ..model.lattice import Lattice


def add_arguments(p) -> None:
    p.add_argument("--n", type=int, default=30, help="the n³-group curved lattice (default 30; the issue's is 40)")
    p.add_argument("--levels", type=int, default=2, help="refinement levels of the refined rows (default 2)")
    p.add_argument("--styles", default="cnt,refined", help="comma-separated styles (default cnt,refined)")


def curved_lattice(n: int, radius: float = 0.08) -> Lattice:
    """Translation U, rotation V about z, swirl W (rotation about y with a slight shrink)."""
    lat = Lattice()
    a = lat.add_node((0.0, 0.0, 0.0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation((1.0, 0.0, 0.0)))
    lat.set_v(n, Rotation(0.03, (0.0, 0.0, 1.0), (-30.0, 0.0, 0.0)))
    lat.set_w(n, Swirl(0.008, (0.0, 1.0, 0.0), (120.0, 0.0, 0.0), 0.998))
    return lat


def regular_lattice(n: int, radius: float = 0.08) -> Lattice:
    lat = Lattice()
    a = lat.add_node((0.0, 0.0, 0.0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation((1.0, 0.0, 0.0)))
    lat.set_v(n, Translation((0.0, 1.0, 0.0)))
    lat.set_w(n, Translation((0.0, 0.0, 1.0)))
    return lat


def _stream(lat: Lattice, style: str, levels: int, batched: bool, workers: int, path: str) -> dict:
    r = lat.region()
    t0 = time.perf_counter()
    tess = _Tessellator(lat, r, style, levels, 16, batched=batched)
    n = write_stl(path, iter_triangles(lat, r, style, levels, _tess=tess, workers=workers), grid=output_grid(lat, r),
                  workers=workers)
    dt = time.perf_counter() - t0
    return {"path": "batched" if batched else "per-hub", "workers": workers, "seconds": round(dt, 3),
            "triangles": n, "triangles_per_s": round(n / dt), "hub_templates": len(tess.templates)}


def _writer_only(lat: Lattice, style: str, levels: int, path: str) -> dict:
    chunks = list(iter_triangles(lat, None, style, levels))
    t0 = time.perf_counter()
    n = write_stl(path, chunks, grid=output_grid(lat))
    dt = time.perf_counter() - t0
    return {"seconds": round(dt, 3), "triangles": n, "triangles_per_s": round(n / dt)}


def run(args) -> dict:
    if not 2 <= args.n <= 200:
        raise PleError(f"--n {args.n}: expected 2..200")
    styles = [s.strip() for s in args.styles.split(",") if s.strip()]
    rows = []
    with tempfile.TemporaryDirectory(prefix="ple-bench-curved-") as d:
        path = os.path.join(d, "out.stl")
        for name, lat in (("curved", curved_lattice(args.n)), ("regular", regular_lattice(args.n))):
            for style in styles:
                levels = args.levels if style == "refined" else 0
                runs = [_stream(lat, style, levels, False, 1, path)] if name == "curved" else []
                runs += [_stream(lat, style, levels, True, w, path) for w in (1, 2)]
                row = {"lattice": name, "groups": lat.groups, "beams": lat.beam_count(), "style": style,
                       "levels": levels, "runs": runs}
                if name == "curved":
                    base = runs[0]["seconds"]
                    row["speedup_batched_1_worker"] = round(base / runs[1]["seconds"], 2)
                    row["speedup_batched_2_workers"] = round(base / runs[2]["seconds"], 2)
                    row["stl_writer_only"] = _writer_only(lat, style, levels, path)
                rows.append(row)
    return {"benchmark": "curved", "n": args.n, "machine": f"{os.cpu_count()} cores (shared, loaded)",
            "rows": rows, "peak_rss_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6, 2)}
