"""BIQ (thesis §7.4 protocol): 100 random query balls on the thesis lattices, RangeFinder vs naive."""

from __future__ import annotations

import os
import time

import numpy as np

from ..program.sources import load_lattice
from ..queries.biq import query
from ._timing import best_of

THESIS_MS = {"thesis_regular": 5.86, "thesis_cylindrical": 55.4, "thesis_warped": 3680.0}
THESIS_NAIVE_S = {"thesis_regular": 55.2, "thesis_cylindrical": 259.0, "thesis_warped": 167.0}


def add_arguments(p) -> None:
    p.add_argument("--lattices", default="thesis_regular,thesis_cylindrical,thesis_warped",
                   help="comma-separated presets or files")
    p.add_argument("--queries", type=int, default=100, help="query balls per lattice (default 100)")
    p.add_argument("--naive-queries", type=int, default=2,
                   help="queries timed on the naive path, extrapolated to --queries (default 2)")
    p.add_argument("--seed", type=int, default=2024)


def protocol_queries(lat, count: int, seed: int):
    """Centres uniform in the lattice's bounding box, radii 90–110 % of the mean ball radius."""
    rng = np.random.default_rng(seed)
    lo, hi = lat.bounds()
    return rng.uniform(lo, hi, (count, 3)), rng.uniform(0.9, 1.1, count) * lat.mean_radius()


def run(args) -> dict:
    rows = []
    for name in args.lattices.split(","):
        lat = load_lattice(name)
        c, r = protocol_queries(lat, args.queries, args.seed)
        t0 = time.perf_counter()
        fast = query(lat, c, r, method="rangefinder")  # includes the per-lattice preparation
        cold = time.perf_counter() - t0
        warm = best_of(lambda lat=lat, c=c, r=r: query(lat, c, r, method="rangefinder"), repeat=20)
        m = min(args.naive_queries, args.queries)
        t0 = time.perf_counter()
        slow = query(lat, c[:m], r[:m], method="naive")
        naive = (time.perf_counter() - t0) * args.queries / max(m, 1)
        same = all(np.array_equal(a.nodes, b.nodes) and np.array_equal(a.beams, b.beams)
                   for a, b in zip(slow, fast[:m]))
        rows.append({
            "lattice": name, "counts": list(lat.counts), "nodes": lat.node_count(), "beams": lat.beam_count(),
            "queries": args.queries, "path": fast[0].path if fast else None,
            "hits": int(sum(len(x.nodes) + len(x.beams) for x in fast)),
            "rangefinder_ms": warm * 1e3, "rangefinder_first_call_ms": cold * 1e3,
            "naive_s": naive, "naive_extrapolated_from_queries": m,
            "speedup_vs_naive": naive / warm, "naive_matches_on_timed_queries": same,
            "thesis_rangefinder_ms": THESIS_MS.get(name), "thesis_naive_s": THESIS_NAIVE_S.get(name),
        })
    return {"benchmark": "biq", "protocol": "thesis §7.4: centres uniform in the bounding box, radii 90-110% "
            "of the mean ball radius; RangeFinder time is the best of 20 warm runs, first call separately",
            "cpus": os.cpu_count(), "seed": args.seed, "rows": rows}
