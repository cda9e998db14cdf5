"""Partitioned jobs on Dask: parts/s and triangles/s with 1 and 2 workers, the per-task overhead
of the scheduler (empty parts), peak memory per worker, and a large LiL count streamed in parts."""

from __future__ import annotations

import json
import resource
import tempfile
import time

from ..app.cluster import dask_client, run_job
from ..app.jobs import filter_job, mesh_job


def add_arguments(p) -> None:
    p.add_argument("--lattice", default="octet", help="preset meshed in parts (default: octet)")
    p.add_argument("--n", type=int, default=10, help="preset input n (default 10)")
    p.add_argument("--box-groups", type=int, default=25, help="node-groups per mesh part (default 25)")
    p.add_argument("--lil-n", type=int, default=200, help="fine cubic count per direction of the LiL job (200)")


def _mesh(args, workers: int, tmp: str) -> dict:
    job = mesh_job(args.lattice, [f"n={args.n}"], "cnt", box_groups=args.box_groups)
    with dask_client("local", workers) as client:
        t0 = time.perf_counter()
        run_job(job, f"{tmp}/mesh{workers}", client=client, progress=False)
        dt = time.perf_counter() - t0
        rss = client.run(lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
    manifest = json.load(open(f"{tmp}/mesh{workers}/manifest.json"))
    tri = sum(e["triangles"] for e in manifest["parts"].values())
    return {"workers": workers, "parts": len(job.parts), "seconds": round(dt, 3), "parts_per_s": len(job.parts) / dt,
            "triangles_per_s": tri / dt, "peak_rss_per_worker_mb": round(max(rss.values()) / 2**20, 1)}


def _overhead(tmp: str) -> dict:
    """Seconds per part of a job whose parts do almost nothing (a 1-group filter slab each)."""
    job = filter_job("cubic", ["n=8"], None, 1)
    with dask_client("local", 2) as client:
        t0 = time.perf_counter()
        run_job(job, f"{tmp}/tiny", client=client, progress=False)
        dt = time.perf_counter() - t0
    t0 = time.perf_counter()
    run_job(job, f"{tmp}/tiny_sync", "sync", progress=False)
    sync = time.perf_counter() - t0
    return {"parts": len(job.parts), "dask_s_per_part": dt / len(job.parts), "sync_s_per_part": sync / len(job.parts)}


def run(args) -> dict:
    with tempfile.TemporaryDirectory(prefix="ple-bench-scale-") as tmp:
        one, two = _mesh(args, 1, tmp), _mesh(args, 2, tmp)
        overhead = _overhead(tmp)
        n = args.lil_n
        job = filter_job("cubic", [f"n={n}"], None, 1 << 19,
                         {"lil": {"coarse": {"format": "ple-lattice/1",
                                             "nodes": [{"center": [n / 2, n / 2, n / 2], "radius": n / 3}]}}})
        t0 = time.perf_counter()
        res = run_job(job, f"{tmp}/lil", "local", workers=2, progress=False)
        dt = time.perf_counter() - t0
        manifest = json.load(open(f"{tmp}/lil/manifest.json"))
    kept = sum(e["nodes"] for e in manifest["parts"].values())
    beams = 3 * n * n * (n - 1)
    return {"benchmark": "scale", "machine": "2 cores", "mesh": [one, two],
            "speedup_2_workers": one["seconds"] / two["seconds"], "scheduler_overhead": overhead,
            "lil_job": {"fine_beams": beams, "parts": len(job.parts), "written": res["written"], "kept_nodes": kept,
                        "seconds": round(dt, 2), "beams_per_s": beams / dt}}
