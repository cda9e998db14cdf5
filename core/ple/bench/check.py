"""Unclean-pair search on a 10⁶-beam lattice: the steady path (anchors + RangeFinder) vs a KD-tree over
sampled beam points, in the same run.

The lattice: an n³ cubic lattice (axis struts) with both face diagonals of every xy face, which
cross at the face centre (unclean by construction: (n−1)² n beam–beam pairs). The baseline samples
``--samples`` points along every beam axis (away from the end balls), finds point pairs closer than
2 r + the sample spacing with ``scipy.spatial.cKDTree`` (every overlapping pair of equal-radius
beams has such a pair), then tests the distinct non-incident beam pairs exactly. Both report the
same counts (checked)."""

from __future__ import annotations

import time

import numpy as np

from ..algebra.similarity import Translation
from ..model.lattice import Lattice
from ..queries.overlaps import KINDS, pair_gaps, unclean_pairs


def add_arguments(p) -> None:
    p.add_argument("--n", type=int, default=60, help="groups per direction (default 60: about 10⁶ beams)")
    p.add_argument("--radius", type=float, default=0.08, help="ball radius (default 0.08)")
    p.add_argument("--samples", type=int, default=3, help="baseline sample points per beam (default 3)")
    p.add_argument("--no-baseline", action="store_true", help="skip the KD-tree baseline")


def lattice(n: int, radius: float) -> Lattice:
    lat = Lattice()
    lat.add_node([0, 0, 0], radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0)]:
        lat.add_beam(0, 0, *off)
    lat.set_u(n, Translation([1, 0, 0]))
    lat.set_v(n, Translation([0, 1, 0]))
    lat.set_w(n, Translation([0, 0, 1]))
    return lat


def run(args) -> dict:
    lat = lattice(args.n, args.radius)
    out = {"machine": "2 shared cores", "groups": lat.groups, "beams": lat.beam_count(),
           "expected_beam_beam": (args.n - 1) ** 2 * args.n}
    t0 = time.perf_counter()
    fast = unclean_pairs(lat)
    out["steady"] = {"seconds": round(time.perf_counter() - t0, 3), "pairs": fast["pairs"], "path": fast["path"],
                     "queries": fast.get("queries")}
    if not args.no_baseline:
        out["kdtree"] = _baseline(lat, args.samples)
        out["speedup"] = round(out["kdtree"]["seconds"] / max(out["steady"]["seconds"], 1e-9), 1)
        out["agree"] = out["kdtree"]["pairs"] == fast["pairs"]
    return out


def _baseline(lat: Lattice, samples: int) -> dict:
    from scipy.spatial import cKDTree  # noqa: PLC0415 - optional package

    t0 = time.perf_counter()
    ev = lat.evaluate()
    a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
    ca, cb, r = ev.center[a], ev.center[b], ev.radius[a]
    t = (np.arange(samples) + 0.5) / samples
    pts = (ca[:, None] + t[None, :, None] * (cb - ca)[:, None]).reshape(-1, 3)
    owner = np.repeat(np.arange(len(a)), samples)
    spacing = float(np.max(np.linalg.norm(cb - ca, axis=1))) / samples
    tree = cKDTree(pts)
    pairs = tree.query_pairs(2 * float(r.max()) + spacing, output_type="ndarray")
    i, j = owner[pairs[:, 0]], owner[pairs[:, 1]]
    keep = i != j
    pair = np.unique(np.stack([np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])], axis=1), axis=0)
    i, j = pair[:, 0], pair[:, 1]
    ends_i, ends_j = ev.beam_nodes[i], ev.beam_nodes[j]
    shared = (ends_i[:, :1] == ends_j).any(axis=1) | (ends_i[:, 1:] == ends_j).any(axis=1)
    i, j = i[~shared], j[~shared]
    one = np.ones(len(i), np.int64)
    _, over, _ = pair_gaps(one, ca[i], r[i], (cb[i], ev.radius[b][i]), one, ca[j], r[j], (cb[j], ev.radius[b][j]))
    counts = dict.fromkeys(KINDS, 0)
    counts["beam_beam"] = int(over.sum())
    return {"seconds": round(time.perf_counter() - t0, 3), "points": int(len(pts)), "candidate_pairs": int(len(i)),
            "pairs": counts}
