"""BeCOTS RangeFinder: 1000 BIQs on a 10^6-group BeCOTS lattice vs the general steady-slab path.

Both sides go through ``ple.biq.query`` in the same process on the same queries: the BeCOTS
side by its normal dispatch, the baseline with ``method="rangefinder"`` on a copy of the
lattice whose ``becots`` is None (the dispatch bypassed, so it runs the general steady-slab
RangeFinder). Both are timed on every query (best and median of ``--repeat`` runs), and their
hit sets must be identical."""

from __future__ import annotations

import time

import numpy as np

from ..model.becots import BeCOTSField
from ..model.becots_builders import becots_lattice, stack_lattice
from ..queries import biq
from ..queries.becots_rangefinder import query, stack_pmc
from ..queries.plans import forget
from ._timing import best_of


def add_arguments(p) -> None:
    p.add_argument("--n", type=int, default=1000, help="nu = nv (default 1000: 10^6 node-groups)")
    p.add_argument("--queries", type=int, default=1000, help="number of BIQs (default 1000)")
    p.add_argument("--layers", type=int, default=20, help="layers of the stack PMC benchmark (default 20)")
    p.add_argument("--repeat", type=int, default=30, help="timed runs of the BeCOTS side (default 30)")
    p.add_argument("--baseline-repeat", type=int, default=3, help="timed runs of the general path (default 3)")
    p.add_argument("--baseline-queries", type=int, default=0,
                   help="queries timed on the general path (default 0: all of them; fewer are scaled per query)")


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


def _timed(fn, repeat: int) -> dict:
    """Best and median wall time and process CPU time (seconds) of ``repeat`` calls. On a
    shared machine a long run is preempted and its wall time inflated; CPU time is not."""
    wall, cpu = [], []
    for _ in range(max(1, repeat)):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return {"wall_best": min(wall), "wall_median": float(np.median(wall)), "cpu_best": min(cpu),
            "cpu_median": float(np.median(cpu))}


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(np.array_equal(x.nodes, y.nodes) and np.array_equal(x.beams, y.beams)
                                    for x, y in zip(a, b))


def run(args) -> dict:
    fld = BeCOTSField.from_corners([0, 0, 0], [0.3, 40, 3], [50, 50, 20], [45, -3, 2])
    lat = becots_lattice(fld, (args.n, args.n), "triangle", 0.08)
    general = lat.copy()
    general.becots = None  # bypass the BeCOTS dispatch: the general steady-slab RangeFinder
    rng = np.random.default_rng(0)
    rows = []
    for near in (False, True):
        c, r = _queries(lat, rng, args.queries, near)
        forget(lat)
        t0 = time.perf_counter()
        res = biq.query(lat, c, r)  # the first call builds and caches the per-lattice plan
        t_first = time.perf_counter() - t0
        t = _timed(lambda c=c, r=r: biq.query(lat, c, r), args.repeat)
        nb = args.queries if args.baseline_queries <= 0 else max(1, min(args.baseline_queries, args.queries))
        base = biq.query(general, c[:nb], r[:nb], method="rangefinder")
        g = _timed(lambda c=c[:nb], r=r[:nb]: biq.query(general, c, r, method="rangefinder"), args.baseline_repeat)
        g = {k: v * args.queries / nb for k, v in g.items()}  # scaled to all queries
        ms = lambda d: {k: round(v * 1e3, 3) for k, v in d.items()}  # noqa: E731
        speed = {k: round(g[k] / t[k], 1) for k in t}
        rows.append({"queries": "near nodes" if near else "uniform in box", "n_queries": args.queries,
                     "path": res[0].path, "hits": sum(len(x.nodes) + len(x.beams) for x in res),
                     "becots_ms": ms(t), "becots_repeats": args.repeat,
                     "becots_ms_first_call_with_plan": round(t_first * 1e3, 3),
                     "baseline": f"ple.biq.query(method='rangefinder'), BeCOTS dispatch bypassed, path {base[0].path}",
                     "baseline_queries_timed": nb, "baseline_repeats": args.baseline_repeat, "baseline_ms": ms(g),
                     "speedup": speed, "identical_hits": _same(res[:nb], base),
                     "under_50ms": t["wall_median"] < 0.05,
                     "speedup_100x_wall_best": speed["wall_best"] >= 100,
                     "speedup_100x_cpu_best": speed["cpu_best"] >= 100})
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
