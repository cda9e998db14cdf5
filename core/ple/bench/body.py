"""Body-fill benchmark: a lattice of about 10⁶ nodes filling the demo bracket (presets/bracket.stl)
by each fill mode, against the user's alternative, a loop over the nodes asking trimesh for each
node's signed distance (the ``inside`` test: centre inside and at least a radius from the surface).

The loop is timed on a random sample of the nodes (it runs at milliseconds per node) and its
seconds for all nodes are extrapolated from that sample; the sample's answers are compared with
the body filter's, so the speed-up is between two tests that agree.
"""

from __future__ import annotations

import os
import time

import numpy as np
import trimesh

from ..algebra.similarity import Translation
from ..filters.body import MODES, BodyFilter
from ..io.bodyfile import load_body
from ..model.lattice import Lattice
from ..program.presets import preset_dir
from ._timing import best_of


def add_arguments(p) -> None:
    p.add_argument("--nodes", type=float, default=1e6, help="about this many lattice nodes (default 1e6)")
    p.add_argument("--body", help="a closed mesh file (default: the demo bracket of the presets)")
    p.add_argument("--sample", type=int, default=500, help="nodes timed in the per-node trimesh loop (default 500)")
    p.add_argument("--repeat", type=int, default=2, help="best of this many runs (default 2)")


def bcc(lo, hi, nodes: float) -> Lattice:
    """A BCC lattice (2 balls per cell, 8 beams) over the box lo..hi with about ``nodes`` balls."""
    size = np.asarray(hi) - np.asarray(lo)
    cell = float((np.prod(size) / (nodes / 2)) ** (1 / 3))
    counts = np.maximum(np.ceil(size / cell).astype(int), 1)
    lat = Lattice()
    a = lat.add_node(lo, 0.15 * cell)
    b = lat.add_node(np.asarray(lo) + cell / 2, 0.15 * cell)
    for off in ((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)):
        lat.add_beam(a, b, *(-o for o in off))
    lat.set_u(int(counts[0]), Translation(np.array([cell, 0, 0])))
    lat.set_v(int(counts[1]), Translation(np.array([0, cell, 0])))
    lat.set_w(int(counts[2]), Translation(np.array([0, 0, cell])))
    return lat


def run(args) -> dict:
    path = args.body or str(preset_dir() / "bracket.stl")
    t0 = time.perf_counter()
    body = load_body(path)
    load_s = time.perf_counter() - t0
    lat = bcc(body.lo, body.hi, args.nodes)
    ev = lat.evaluate()
    out = {"benchmark": "body", "body": os.path.basename(path), "triangles": len(body.faces),
           "machine": f"{os.cpu_count()} cores", "nodes": len(ev.center), "load_seconds": load_s,
           "evaluate_unfiltered_seconds": best_of(lat.evaluate, args.repeat), "modes": {}}
    for mode in MODES:
        fresh = lambda m=mode: lat.with_filter(BodyFilter(load_body(path), m)).evaluate()  # noqa: E731 - cold caches
        kept = fresh()
        decide = lambda m=mode: BodyFilter(load_body(path), m).node_mask(  # noqa: E731 - the decision alone
            lat, ev.node_index, ev.center, ev.radius)
        out["modes"][mode] = {"seconds_filter_only": best_of(decide, args.repeat),
                              "seconds_with_evaluation": best_of(fresh, args.repeat),
                              "nodes_kept": len(kept.center), "beams_kept": len(kept.beam_nodes)}
    # the baseline: one trimesh signed-distance call per node, on a random sample
    mesh = trimesh.load(path, force="mesh")
    rng = np.random.default_rng(0)
    rows = rng.choice(len(ev.center), size=min(args.sample, len(ev.center)), replace=False)
    t0 = time.perf_counter()
    loop = np.array([trimesh.proximity.signed_distance(mesh, ev.center[n:n + 1])[0] >= ev.radius[n] for n in rows])
    loop_s = time.perf_counter() - t0
    ours = BodyFilter(body, "inside").node_mask(lat, ev.node_index[rows], ev.center[rows], ev.radius[rows])
    per_node = loop_s / len(rows)
    ple_s = out["modes"]["inside"]["seconds_filter_only"]
    out["baseline_trimesh_per_node_loop"] = {
        "sample_nodes": len(rows), "sample_seconds": loop_s, "seconds_per_node": per_node,
        "extrapolated_seconds_all_nodes": per_node * len(ev.center),
        "sample_agreement": float(np.mean(loop == ours))}
    out["speedup_inside_filter_vs_loop"] = per_node * len(ev.center) / ple_s
    return out
