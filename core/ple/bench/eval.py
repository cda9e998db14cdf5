"""Lazy evaluation throughput: nodes per second for regions of growing size."""

from __future__ import annotations

import numpy as np

from ..model.lattice import Lattice
from ..program.sources import load_lattice
from ._timing import best_of


def add_arguments(p) -> None:
    p.add_argument("--lattice", default="warped", help="preset or file (default: warped)")


def _matrix_power_loop(lat: Lattice, n: int) -> None:
    """Baseline: what a plain per-group loop does — a matrix-power chain per group."""
    mu, mv, mw = lat.U.matrix, lat.V.matrix, lat.W.matrix
    c = np.append(lat.template_centers[0], 1.0)
    for i in range(n):
        for j in range(n):
            for k in range(n):
                np.linalg.matrix_power(mw, k) @ np.linalg.matrix_power(mv, j) @ np.linalg.matrix_power(mu, i) @ c


def _row(lat: Lattice, n: int) -> dict:
    sub = lat.with_counts(n, n, n)
    nodes = sub.node_count()
    t_region = best_of(lambda: sub.region_balls())
    rng = np.random.default_rng(0)
    idx = np.stack([rng.integers(0, n, nodes), rng.integers(0, n, nodes), rng.integers(0, n, nodes),
                    rng.integers(0, len(sub.nodes), nodes)], axis=1)
    t_random = best_of(lambda: sub.node_balls(idx))
    m = min(n, 10)
    t_loop = best_of(lambda: _matrix_power_loop(sub, m), repeat=1) * sub.groups / m**3 * len(sub.nodes)
    return {"groups": sub.groups, "nodes": nodes, "region_s": t_region, "random_index_s": t_random,
            "region_nodes_per_s": nodes / t_region, "matrix_power_loop_s_extrapolated": t_loop,
            "speedup_vs_loop": t_loop / t_region}


def run(args) -> dict:
    lat = load_lattice(args.lattice)
    return {"benchmark": "eval", "lattice": args.lattice, "rows": [_row(lat, n) for n in (10, 50, 100)]}
