"""BIQ benchmarks, every baseline timed in the same run.

- ``rows``: the thesis §7.4 protocol (100 random query balls on the thesis lattices), RangeFinder
  against the naive BIQ: the lattice evaluated once, then each query tested exactly against
  every element, vectorized in numpy over all elements (``_baselines.naive_hits``); timed on
  ``--naive-queries`` queries and scaled to ``--queries``. The thesis' own figures (Java,
  i7-7700K, one thread: Table 7.2 and §7.4) stand beside them, unscaled.
- ``kdtree``: the user's alternative on a curved lattice (default ``thesis_warped``, 100³, Fig.
  7.10): a prebuilt ``scipy.spatial.cKDTree`` over the ball centres (nodes only) and over the
  centres and beam midpoints (nodes and beams), exact tests vectorized, against
  ``biq.query(..., beams=False)`` and ``biq.query(...)``; 1,000 BIQs, half uniform in the
  bounds (radii 90–110 % of the mean radius), half at random nodes plus noise with 3× the
  node's radius. The tree's evaluation and build times are shown beside its query times; PLE
  evaluates nothing (its first call builds the per-lattice plan, shown separately). ``form``
  says whether the compiled pulled-back query answered (``ple.queries._rangefinder``) or numpy.
"""

from __future__ import annotations

import os
import time

import numpy as np

from ..program.sources import load_lattice
from ..queries import pullback
from ..queries.biq import query
from ..queries.plans import forget
from ._baselines import CentreTree, Elements, ElementTree, naive_hits
from ._timing import best_of

# thesis §7.4 / Table 7.2 (one thread, i7-7700K, Java): 100 BIQs, best path and naive
THESIS_MS = {"thesis_regular": 5.86, "thesis_cylindrical": 55.4, "thesis_warped": 3680.0}
THESIS_NAIVE_S = {"thesis_regular": 55.2, "thesis_cylindrical": 259.0, "thesis_warped": 167.0}


def add_arguments(p) -> None:
    p.add_argument("--lattices", default="thesis_regular,thesis_cylindrical,thesis_warped",
                   help="comma-separated presets or files")
    p.add_argument("--queries", type=int, default=100, help="query balls per lattice (default 100)")
    p.add_argument("--naive-queries", type=int, default=5,
                   help="queries timed on the naive baseline, scaled to --queries (default 5)")
    p.add_argument("--tree-lattice", default="thesis_warped",
                   help="the curved lattice of the KD-tree comparison (default thesis_warped, 100³; '' skips)")
    p.add_argument("--tree-queries", type=int, default=1000, help="BIQs of the KD-tree comparison (default 1000)")
    p.add_argument("--repeat", type=int, default=20, help="timed runs of each warm query set, best kept (default 20)")
    p.add_argument("--seed", type=int, default=2024)


def protocol_queries(lat, count: int, seed: int):
    """Centres uniform in the lattice's bounding box, radii 90–110 % of the mean ball radius."""
    rng = np.random.default_rng(seed)
    lo, hi = lat.bounds()
    return rng.uniform(lo, hi, (count, 3)), rng.uniform(0.9, 1.1, count) * lat.mean_radius()


def near_node_queries(lat, count: int, seed: int, scale: float = 3.0):
    """Balls at random nodes plus noise (normal, σ the node's radius), radius ``scale`` × the node's."""
    rng = np.random.default_rng(seed)
    idx = np.stack([rng.integers(0, n, count) for n in lat.counts] + [rng.integers(0, len(lat.nodes), count)], axis=1)
    c, r = lat.node_balls(idx)
    return c + rng.normal(size=(count, 3)) * r[:, None], scale * r


def _same(results, node_index, beam_index, node_hits, beam_hits, beams: bool = True) -> bool:
    """Do PLE's per-query results hold exactly the baseline's (qid, row) hits?"""
    want = [(node_index[node_hits[node_hits[:, 0] == t, 1]], beam_index[beam_hits[beam_hits[:, 0] == t, 1]])
            for t in range(len(results))]
    key = lambda a: {tuple(x) for x in a}  # noqa: E731
    return all(key(x.nodes) == key(n) and (not beams or key(x.beams) == key(b)) for x, (n, b) in zip(results, want))


def protocol_row(name: str, args) -> dict:
    lat = load_lattice(name)
    c, r = protocol_queries(lat, args.queries, args.seed)
    t0 = time.perf_counter()
    fast = query(lat, c, r, method="rangefinder")  # includes the per-lattice preparation
    cold = time.perf_counter() - t0
    warm = best_of(lambda: query(lat, c, r, method="rangefinder"), repeat=args.repeat)
    t0 = time.perf_counter()
    el = Elements.of(lat)
    t_eval = time.perf_counter() - t0
    m = max(1, min(args.naive_queries, args.queries))
    t0 = time.perf_counter()
    nh, bh = naive_hits(el, c[:m], r[:m])
    naive = (time.perf_counter() - t0) * args.queries / m
    return {
        "lattice": name, "counts": list(lat.counts), "nodes": lat.node_count(), "beams": lat.beam_count(),
        "queries": args.queries, "path": fast[0].path if fast else None,
        "hits": int(sum(len(x.nodes) + len(x.beams) for x in fast)),
        "rangefinder_ms": warm * 1e3, "rangefinder_first_call_ms": cold * 1e3,
        "naive_s": naive, "naive_scaled_from_queries": m, "naive_evaluation_s": t_eval,
        "naive": "every element tested exactly per query, vectorized in numpy over all elements "
                 "(the lattice evaluated once, naive_evaluation_s, not included)",
        "speedup_vs_naive": naive / warm, "naive_matches_on_timed_queries": _same(fast[:m], el.node_index,
                                                                                  el.beam_index, nh, bh),
        "thesis_rangefinder_ms": THESIS_MS.get(name), "thesis_naive_s": THESIS_NAIVE_S.get(name),
        "thesis": "Java, one thread, i7-7700K (thesis Table 7.2, §7.4), unscaled",
    }


def kdtree_row(args) -> dict:
    """PLE against a prebuilt cKDTree, nodes only and nodes and beams (module doc)."""
    lat = load_lattice(args.tree_lattice)
    half = args.tree_queries // 2
    cu, ru = protocol_queries(lat, args.tree_queries - half, args.seed)
    cn, rn = near_node_queries(lat, half, args.seed + 1)
    c, r = np.concatenate([cu, cn]), np.concatenate([ru, rn])
    q = len(c)
    forget(lat)
    t0 = time.perf_counter()
    query(lat, c, r, beams=False)
    plan_nodes = time.perf_counter() - t0
    t0 = time.perf_counter()
    query(lat, c, r)
    plan_both = time.perf_counter() - t0
    out = {}
    t_nodes = best_of(lambda: out.__setitem__("nodes", query(lat, c, r, beams=False)), args.repeat)
    t_both = best_of(lambda: out.__setitem__("both", query(lat, c, r)), args.repeat)
    t0 = time.perf_counter()
    el = Elements.of(lat)
    t_eval = time.perf_counter() - t0
    t0 = time.perf_counter()
    centres = CentreTree(el)
    build_nodes = time.perf_counter() - t0
    t0 = time.perf_counter()
    elements = ElementTree(el)
    build_both = time.perf_counter() - t0
    t_tree_nodes = best_of(lambda: out.__setitem__("tree_nodes", centres.nodes(c, r)), args.repeat)
    t_tree_both = best_of(lambda: out.__setitem__("tree_both", elements.hits(c, r)), args.repeat)
    tn, (tbn, tbb) = out["tree_nodes"], out["tree_both"]
    none = np.zeros((0, 2), np.int64)
    return {
        "lattice": args.tree_lattice, "counts": list(lat.counts), "nodes": lat.node_count(),
        "beams": lat.beam_count(), "queries": q, "uniform_queries": len(cu), "near_node_queries": len(cn),
        "path": out["both"][0].path, "node_hits": int(len(tn)), "beam_hits": int(len(tbb)),
        "repeat": args.repeat,
        "nodes_only": {
            "ple_ms": t_nodes * 1e3, "ple_us_per_query": t_nodes * 1e6 / q, "ple_first_call_ms": plan_nodes * 1e3,
            "tree_ms": t_tree_nodes * 1e3, "tree_us_per_query": t_tree_nodes * 1e6 / q,
            "tree_build_s": build_nodes, "evaluation_s": t_eval,
            "speedup_vs_tree": t_tree_nodes / t_nodes,
            "same_hits": _same(out["nodes"], el.node_index, el.beam_index, tn, none, beams=False),
        },
        "nodes_and_beams": {
            "ple_ms": t_both * 1e3, "ple_us_per_query": t_both * 1e6 / q, "ple_first_call_ms": plan_both * 1e3,
            "tree_ms": t_tree_both * 1e3, "tree_us_per_query": t_tree_both * 1e6 / q,
            "tree_build_s": build_both, "evaluation_s": t_eval,
            "speedup_vs_tree": t_tree_both / t_both,
            "same_hits": _same(out["both"], el.node_index, el.beam_index, tbn, tbb),
        },
        "form": "compiled" if pullback.cached_pullback(lat).kernel is not None else "numpy",
        "load_average_1min": os.getloadavg()[0],
        "note": "times are the best of `repeat` warm runs of all queries; the tree's evaluation and build are "
                "not in its query times, PLE's plan is not in its (first_call_ms: the first call, plan included)",
    }


def run(args) -> dict:
    rows = [protocol_row(name, args) for name in args.lattices.split(",") if name]
    out = {"benchmark": "biq", "protocol": "thesis §7.4: centres uniform in the bounding box, radii 90-110% "
           f"of the mean ball radius; RangeFinder time is the best of {args.repeat} warm runs, first call separately",
           "cpus": os.cpu_count(), "seed": args.seed, "rows": rows}
    if args.tree_lattice:
        out["kdtree"] = kdtree_row(args)
    return out
