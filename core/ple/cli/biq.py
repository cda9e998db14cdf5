"""``ple biq LATTICE --queries Q.npy --out H.json [--method auto|naive|rangefinder]`` (SPEC §6)."""

from __future__ import annotations

import json

import numpy as np

from ..errors import PleError
from ..io.files import atomic_write_text
from ..queries.biq import query
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("biq", help="ball-interference queries: nodes and beams hit by each query ball")
    add_lattice_args(p)
    p.add_argument("--queries", required=True, help="query balls, .npy array (q, 4) of x, y, z, r")
    p.add_argument("--out", required=True, help="output .json")
    p.add_argument("--method", choices=("auto", "naive", "rangefinder"), default="auto",
                   help="auto (RangeFinder) or the naive reference")
    p.set_defaults(func=run)


def load_queries(path: str) -> np.ndarray:
    """Read and check Q (q, 4): finite centres, radii >= 0."""
    try:
        q = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise PleError(f"--queries {path}: cannot read a .npy array ({exc})") from None
    if q.ndim != 2 or q.shape[1] != 4:
        raise PleError(f"--queries {path}: expected shape (q, 4) of x, y, z, r, got {q.shape}")
    if not np.issubdtype(q.dtype, np.number):
        raise PleError(f"--queries {path}: expected numbers, got dtype {q.dtype}")
    q = q.astype(float)
    if not np.all(np.isfinite(q)):
        raise PleError(f"--queries {path}: NaN or infinite values")
    if np.any(q[:, 3] < 0):
        raise PleError(f"--queries {path}: negative radius in row {int(np.argmax(q[:, 3] < 0))}")
    return q


def run(args) -> int:
    if not args.out.endswith(".json"):
        raise PleError(f"--out {args.out}: expected a .json file")
    q = load_queries(args.queries)
    lat = lattice_from_args(args)
    results = query(lat, q[:, :3], q[:, 3], method=args.method)
    doc = {"queries": [{"nodes": r.nodes.tolist(), "beams": r.beams.tolist()} for r in results]}
    atomic_write_text(args.out, json.dumps(doc) + "\n")
    path = results[0].path if results else "-"
    hits = sum(len(r.nodes) + len(r.beams) for r in results)
    print(f"wrote {args.out}: {len(results)} queries, {hits} hits (path {path})")
    return 0
