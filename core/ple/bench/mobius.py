"""BIQ on Möbius lattices: the pre-image RangeFinder (thesis §11.2.1, §11.3) vs every element, same run."""

from __future__ import annotations

import os
import time

import numpy as np

from ..algebra.mobius import Cline, Mobius
from ..algebra.similarity import Swirl
from ..algebra.vectors import Pt, Vec
from ..model.lattice import Lattice
from ..model.mobius import mobius_lattice
from ..program.sources import load_lattice
from ..queries.biq import query
from ..queries.plans import forget
from ._timing import best_of


def add_arguments(p) -> None:
    p.add_argument("--tmi", type=int, default=150, help="TMI slab cells per side (tmi_slab preset; default 150)")
    p.add_argument("--row", type=int, default=20000, help="groups of the loxodromic 1-pattern (default 20000)")
    p.add_argument("--frames", type=int, default=60,
                   help="Möbius-frame slab cells per side (mobius_slab: U, V do not commute; default 60)")
    p.add_argument("--queries", type=int, default=100, help="query balls per lattice (default 100)")
    p.add_argument("--seed", type=int, default=2024)


def loxodrome_row(count: int) -> Lattice:
    """A Möbius 1-pattern: a swirl seen through a circle inversion (§11.2.1), two balls and three
    beam-patterns per group, spiralling from one fixed point towards the other."""
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), 0.05)
    b = cell.add_node(Pt(0.3, 0.2, 0.02), 0.03)
    cell.add_beam(a, b)
    cell.add_beam(a, a, 1, 0, 0)
    cell.add_beam(b, a, 1, 0, 0)
    u = Mobius.conjugated(Swirl(0.01, Vec(0, 0, 1), Pt(2, 1, 0), 0.9999), Cline.circle(-3 + 1j, 2.5))
    return mobius_lattice(cell, u, None, None, (count, 1, 1))


def _row(name: str, lat: Lattice, count: int, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    lo, hi = lat.bounds()
    c, r = rng.uniform(lo, hi, (count, 3)), rng.uniform(0.9, 1.1, count) * lat.mean_radius()
    forget(lat)
    t0 = time.perf_counter()
    fast = query(lat, c, r)  # includes building the pre-image lattice
    cold = time.perf_counter() - t0
    warm = best_of(lambda: query(lat, c, r), repeat=5)
    t0 = time.perf_counter()
    slow = query(lat, c, r, method="naive")
    naive = time.perf_counter() - t0
    same = all(np.array_equal(a.nodes, b.nodes) and np.array_equal(a.beams, b.beams) for a, b in zip(fast, slow))
    return {"lattice": name, "counts": list(lat.counts), "nodes": lat.node_count(), "beams": lat.beam_count(),
            "queries": count, "path": fast[0].path, "hits": int(sum(len(x.nodes) + len(x.beams) for x in fast)),
            "mobius_ms": warm * 1e3, "mobius_first_call_ms": cold * 1e3, "naive_ms": naive * 1e3,
            "speedup_vs_naive": naive / warm, "same_hits": same}


def run(args) -> dict:
    rows = [
        _row(f"tmi_slab nu=nv={args.tmi}", load_lattice("tmi_slab", {"nu": args.tmi, "nv": args.tmi}),
             args.queries, args.seed),
        _row(f"loxodrome row of {args.row}", loxodrome_row(args.row), args.queries, args.seed),
        _row(f"mobius_slab nu=nv={args.frames}", load_lattice("mobius_slab", {"nu": args.frames, "nv": args.frames}),
             args.queries, args.seed),
    ]
    return {"benchmark": "mobius", "protocol": "thesis §7.4 queries (centres uniform in the bounding box, radii "
            "90-110% of the mean ball radius); the pre-image RangeFinder's best of 5 warm runs and its first "
            "call against the vectorized naive path (every element tested, O(N)) on the same queries, same run",
            "cpus": os.cpu_count(), "seed": args.seed, "rows": rows}
