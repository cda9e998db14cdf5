"""BeCOTS RangeFinder: 1000 BIQs on a 10^6-group BeCOTS lattice vs the general steady-slab path."""

from __future__ import annotations

import time

import numpy as np

from ..becots import BeCOTSField, becots_lattice, stack_lattice, stack_pmc
from ..becots_rangefinder import query
from ._timing import best_of


def add_arguments(p) -> None:
    p.add_argument("--n", type=int, default=1000, help="nu = nv (default 1000: 10^6 node-groups)")
    p.add_argument("--queries", type=int, default=1000, help="number of BIQs (default 1000)")
    p.add_argument("--layers", type=int, default=20, help="layers of the stack PMC benchmark (default 20)")
    p.add_argument("--baseline-queries", type=int, default=20,
                   help="queries timed on the general path (it is slow; its time is scaled per query)")


def _queries(lat, rng, q: int, near: bool):
    """Balls with radii 90-110 % of the mean ball radius: uniform in the lattice's box, or at
    random nodes plus noise (so that most queries hit something)."""
    r = rng.uniform(0.9, 1.1, q) * lat.mean_radius()
    if not near:
        lo, hi = lat.bounds()
        return rng.uniform(lo, hi, (q, 3)), r
    nu, nv, _ = lat.counts
    idx = np.stack([rng.integers(0, nu, q), rng.integers(0, nv, q), np.zeros(q, int), np.zeros(q, int)], axis=1)
    c, rad = lat.node_balls(idx)
    return c + rng.normal(size=(q, 3)) * rad[:, None], r


def run(args) -> dict:
    from ..rangefinder import lattice_hits

    fld = BeCOTSField.from_corners([0, 0, 0], [0.3, 40, 3], [50, 50, 20], [45, -3, 2])
    lat = becots_lattice(fld, (args.n, args.n), "triangle", 0.08)
    rng = np.random.default_rng(0)
    rows = []
    for near in (False, True):
        c, r = _queries(lat, rng, args.queries, near)
        t_becots = best_of(lambda c=c, r=r: query(lat, c, r))
        res = query(lat, c, r)
        hits = sum(len(x.nodes) + len(x.beams) for x in res)
        nb = max(1, min(args.baseline_queries, args.queries))
        t0 = time.perf_counter()
        nh, bh, path = lattice_hits(lat, c[:nb], r[:nb])
        t_base = (time.perf_counter() - t0) / nb * args.queries
        # the general path must agree on the queries it ran
        sub = query(lat, c[:nb], r[:nb])
        agree = (sum(len(x.nodes) for x in sub) == len(np.unique(nh, axis=0))
                 and sum(len(x.beams) for x in sub) == len(np.unique(bh, axis=0)))
        rows.append({"queries": "near nodes" if near else "uniform in box", "n_queries": args.queries,
                     "becots_rangefinder_s": t_becots, "becots_ms_per_1000": t_becots * 1000 * 1000 / args.queries,
                     "hits": hits, "baseline_path": f"ple.rangefinder.lattice_hits ({path})",
                     "baseline_queries_timed": nb, "baseline_s_scaled_to_all_queries": t_base,
                     "speedup": t_base / t_becots, "baseline_agrees": bool(agree)})
    return {"benchmark": "becots", "groups": lat.groups, "nodes": lat.node_count(), "beams": lat.beam_count(),
            "machine": "2 shared cores", "rows": rows, "stack_pmc": _stack_row(fld, args, rng)}


def _stack_row(fld, args, rng) -> dict:
    """PMC on a BeCOTS stack: two nearest layers (§6.3) vs the RangeFinder over every layer."""
    n = max(2, args.n // 4)
    lat = stack_lattice(fld, (n, n), args.layers, 0.3, "normal", "triangle", 0.1, links=((0, 0, 0, 0),))
    nu, nv, _ = lat.counts
    q = args.queries
    idx = np.stack([rng.integers(0, nu, q), rng.integers(0, nv, q), np.zeros(q, int),
                    rng.integers(0, len(lat.nodes), q)], axis=1)
    c, rad = lat.node_balls(idx)
    pts = c + rng.normal(size=(q, 3)) * rad[:, None]
    t_two = best_of(lambda: stack_pmc(lat, pts))
    t_all = best_of(lambda: query(lat, pts, np.zeros(q)))
    same = bool(np.array_equal(stack_pmc(lat, pts), np.array([len(x.nodes) + len(x.beams) > 0
                                                              for x in query(lat, pts, np.zeros(q))])))
    return {"groups": lat.groups, "layers": args.layers, "points": q, "two_nearest_layers_s": t_two,
            "all_layers_rangefinder_s": t_all, "speedup": t_all / t_two, "agree": same}
