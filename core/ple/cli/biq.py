"""``ple biq LATTICE --queries Q.npy --out H.json [--method auto|naive|rangefinder] [--nodes-only]`` (SPEC §6)."""

from __future__ import annotations

import numpy as np

from ..errors import PleError
from ..io.files import atomic_write_text, strict_json
from ..io.inputs import load_npy
from ..model.budget import HIT_ARRAY_BYTES, HIT_LISTED_BYTES, HUGE, estimate_hits, rangefinder_bytes, require
from ..queries.biq import query
from ..queries.rangefinder import cached_plan
from .common import add_lattice_args, lattice_from_args, max_memory


def register(sub) -> None:
    p = sub.add_parser("biq", help="ball-interference queries: nodes and beams hit by each query ball")
    add_lattice_args(p)
    p.add_argument("--queries", required=True, help="query balls, .npy array (q, 4) of x, y, z, r")
    p.add_argument("--out", required=True, help="output .json")
    p.add_argument("--method", choices=("auto", "naive", "rangefinder"), default="auto",
                   help="auto (RangeFinder) or the naive reference")
    p.add_argument("--nodes-only", action="store_true",
                   help="node hits only: no beam is tested, and the output has no \"beams\" lists")
    p.add_argument("--count", action="store_true",
                   help="write only the number of node and beam hits per query (one query at a time in memory)")
    p.set_defaults(func=run)


def load_queries(path: str) -> np.ndarray:
    """Read and check Q (q, 4): finite centres, radii >= 0."""
    q = load_npy(path, "--queries")
    if q.ndim != 2 or q.shape[1] != 4:
        raise PleError(f"--queries {path}: expected shape (q, 4) of x, y, z, r, got {q.shape}")
    if not np.issubdtype(q.dtype, np.number):
        raise PleError(f"--queries {path}: expected numbers, got dtype {q.dtype}")
    q = q.astype(float)
    if not np.all(np.isfinite(q)):
        raise PleError(f"--queries {path}: NaN or infinite values")
    if np.any(np.abs(q) > HUGE):  # their squares must stay finite in the exact tests
        row = int(np.argmax(np.abs(q).max(axis=1) > HUGE))
        raise PleError(f"--queries {path}: values beyond {HUGE:.0e} in row {row} "
                       "(coordinates and radii are at most 1e100, as in lattices)")
    if np.any(q[:, 3] < 0):
        raise PleError(f"--queries {path}: negative radius in row {int(np.argmax(q[:, 3] < 0))}")
    return q


def run(args) -> int:
    if not args.out.endswith(".json"):
        raise PleError(f"--out {args.out}: expected a .json file")
    q = load_queries(args.queries)
    lat = lattice_from_args(args)
    est = estimate_hits(lat, q[:, :3], q[:, 3])
    limit = max_memory(args)
    if args.method != "naive" and lat.becots is None:
        path = cached_plan(lat).path
        require(rangefinder_bytes(lat, path, 1 if args.count else len(q)),
                f"RangeFinder (path {path}) over {lat.counts[0]:,} x {lat.counts[1]:,} rows", limit,
                "use --method naive (memory bounded by a slab, time by the lattice)")
    if args.count:
        most = float(est.max(initial=0))
        require(most * HIT_ARRAY_BYTES, f"the largest query (about {most:,.3g} hits)", limit, "use smaller query balls")
        counts, path = [], "-"
        for row in q:
            (r,) = query(lat, row[None, :3], row[3:4], method=args.method, beams=not args.nodes_only)
            counts.append(_listed(args, len(r.nodes), len(r.beams)))
            path = r.path
        atomic_write_text(args.out, strict_json({"queries": counts}, "the counts") + "\n")
        hits = sum(c["nodes"] + c.get("beams", 0) for c in counts)
        print(f"wrote {args.out}: {len(counts)} queries, {hits} hits counted (path {path})")
        return 0
    require(float(est.sum()) * HIT_LISTED_BYTES, f"listing about {est.sum():,.3g} hits of {len(q)} queries", limit,
            "use --count for the numbers only, or smaller query balls")
    results = query(lat, q[:, :3], q[:, 3], method=args.method, beams=not args.nodes_only)
    doc = {"queries": [_listed(args, r.nodes.tolist(), r.beams.tolist()) for r in results]}
    atomic_write_text(args.out, strict_json(doc, "the hits") + "\n")
    path = results[0].path if results else "-"
    hits = sum(len(r.nodes) + len(r.beams) for r in results)
    print(f"wrote {args.out}: {len(results)} queries, {hits} hits (path {path})")
    return 0


def _listed(args, nodes, beams) -> dict:
    """One query's entry: nodes and beams, or nodes alone with ``--nodes-only``."""
    return {"nodes": nodes} if args.nodes_only else {"nodes": nodes, "beams": beams}
