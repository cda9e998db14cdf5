"""Lazy evaluation throughput: nodes per second for regions of growing size."""

from __future__ import annotations

import numpy as np

from ..program import load_lattice
from ._timing import best_of


def add_arguments(p) -> None:
    p.add_argument("--lattice", default="warped", help="preset or file (default: warped)")


def run(args) -> dict:
    lat = load_lattice(args.lattice)
    rows = []
    for n in (10, 50, 100):
        sub = lat.with_counts(n, n, n)
        nodes = sub.node_count()
        t_region = best_of(lambda: sub.region_balls())
        rng = np.random.default_rng(0)
        idx = np.stack([rng.integers(0, n, nodes), rng.integers(0, n, nodes), rng.integers(0, n, nodes),
                        rng.integers(0, len(sub.nodes), nodes)], axis=1)
        t_random = best_of(lambda: sub.node_balls(idx))
        # baseline: one 4x4 product chain per group, as a plain per-group loop would do (1000 groups)
        mats = [sub.U.matrix, sub.V.matrix, sub.W.matrix]
        t_loop = best_of(lambda: [np.linalg.matrix_power(mats[2], k) @ np.linalg.matrix_power(mats[1], j)
                                  @ np.linalg.matrix_power(mats[0], i) for i in range(10) for j in range(10)
                                  for k in range(10)], repeat=1) * sub.groups / 1000
        rows.append({"groups": sub.groups, "nodes": nodes, "region_s": t_region, "random_index_s": t_random,
                     "region_nodes_per_s": nodes / t_region, "matrix_power_loop_s_estimated": t_loop,
                     "speedup_vs_loop": t_loop / t_region})
    return {"benchmark": "eval", "lattice": args.lattice, "rows": rows}
