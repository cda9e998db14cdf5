"""CLG on non-commuting steady patterns (thesis §5.2): the shelled lattice on a commuting pattern by similar
copies and by the lattice's own nodes, and on a curved pattern whose U, V, W do not commute; PMC, voxels
and meshes in the same run, with the brute-force CSG (every chunk copy) as the baseline and the plain
lattice's RangeFinder PMC of the pattern on the same points beside it."""

from __future__ import annotations

import copy
import json
import os
import time

import numpy as np

from ..clg.grid import voxelize_clg
from ..clg.ir import clg_from_dict
from ..clg.query import Compiled, brute_force_value
from ..meshing.clg import mesh_compiled
from ..program.clg_sources import resolve_clg
from ..queries.biq import pmc as lattice_pmc

CURVED = {"U": {"kind": "translation", "vector": [1, 0, 0]},  # along x
          "V": {"kind": "rotation", "angle": 0.125, "axis": [0, 0, 1], "point": [-8, 0, 0]},  # about z: bends
          "W": {"kind": "scaling", "factor": 1.05, "point": [0, 0, -20]}}  # grows away from a point below


def add_arguments(p) -> None:
    p.add_argument("--counts", type=int, default=20, help="groups per direction (n³ groups, 2 chunks each)")
    p.add_argument("--points", type=int, default=20_000, help="PMC points: half uniform in the box, half near nodes")
    p.add_argument("--brute-points", type=int, default=40, help="points timed by brute force (per-point rate)")
    p.add_argument("--voxels", type=int, default=96, help="voxel grid N (N³)")
    p.add_argument("--mesh-counts", type=int, default=3, help="groups per direction of the meshed case")
    p.add_argument("--seed", type=int, default=7)


def shelled(n: int, curved: bool):
    """The shelled preset with n groups per direction; ``curved``: U, V, W of ``CURVED``."""
    data = copy.deepcopy(json.loads(resolve_clg("shelled").read_text()))
    for axis in "UVW":
        data["pattern"][axis] = {"count": n, "similarity": CURVED[axis] if curved else
                                 data["pattern"][axis]["similarity"]}
    return clg_from_dict(data)


def _timed(f, *args, **kwargs):
    t0 = time.perf_counter()
    out = f(*args, **kwargs)
    return out, time.perf_counter() - t0


def _points(comp, n: int, rng) -> np.ndarray:
    lat = comp.lat
    box = comp.lo + rng.random((n // 2, 3)) * (comp.hi - comp.lo)
    m = n - n // 2
    idx = np.column_stack([rng.integers(0, c, m) for c in lat.counts] + [rng.integers(0, len(lat.nodes), m)])
    c, r = lat.node_balls(idx)
    return np.concatenate([box, c + rng.standard_normal((m, 3)) * r[:, None] * 1.5])


def _case(clg, similar, args) -> dict:
    """PMC (against brute force on the first points), candidates per point and voxels of one CLG."""
    comp, prep = _timed(Compiled, clg, similar=similar)
    pts = _points(Compiled(clg), args.points, np.random.default_rng(args.seed))  # one point set per pattern
    comp.pmc(pts[:100])  # the RangeFinder plan
    inside, secs = _timed(comp.pmc, pts)
    m = min(args.brute_points, len(pts))
    value, slow = _timed(brute_force_value, clg, pts[:m], similar)
    idx = comp.near(pts, np.zeros(len(pts)))
    q = comp.candidates(pts[idx], np.zeros(len(idx)))[0]
    lattice_pmc(clg.pattern, pts[:100])
    _, plain = _timed(lattice_pmc, clg.pattern, pts)  # the pattern's own balls and beams, same points
    nv = args.voxels
    box = Compiled(clg)
    vox, vsecs = _timed(voxelize_clg, comp, box.lo, box.hi, (nv, nv, nv))
    return {"similar_copies": comp.similar, "prepare_s": prep, "points": len(pts), "inside": int(inside.sum()),
            "pmc_s": secs, "pmc_us_per_point": secs / len(pts) * 1e6,
            "candidate_copies_per_point": len(q) / len(pts), "pattern_lattice_pmc_s": plain,
            "brute_force_s_extrapolated": slow / m * len(pts), "brute_force_timed_points": m,
            "pmc_speedup_over_brute_force": slow / m * len(pts) / secs,
            "agree_on_timed_points": bool(np.array_equal(value <= 0, inside[:m])),
            "voxels": [nv, nv, nv], "voxelize_s": vsecs, "voxels_inside": int(vox.sum()),
            "_pmc": inside, "_voxels": vox}


CASES = (("commuting, similar copies", False, None), ("commuting, own nodes", False, False),
         ("curved (non-commuting), own nodes", True, None))


def run(args) -> dict:
    n, nm = args.counts, args.mesh_counts
    out = {"benchmark": "clg_steady", "cpus": os.cpu_count(), "clg": "shelled preset (X − Y, 2 chunks)",
           "counts": [n, n, n], "chunk_copies": 2 * n ** 3, "curved_pattern": CURVED}
    cases = {name: _case(shelled(n, curved), similar, args) for name, curved, similar in CASES}
    base, own = cases["commuting, similar copies"], cases["commuting, own nodes"]
    out["own_nodes_cost_on_the_commuting_pattern"] = {
        "pmc": own["pmc_s"] / base["pmc_s"], "voxelize": own["voxelize_s"] / base["voxelize_s"],
        "pmc_disagreements": int((own.pop("_pmc") != base.pop("_pmc")).sum()),
        "voxel_disagreements": int((own.pop("_voxels") != base.pop("_voxels")).sum())}
    for case in cases.values():
        case.pop("_pmc", None)
        case.pop("_voxels", None)
    out["cases"] = cases
    out["mesh"] = {}
    for name, curved, similar in CASES:
        mesh, secs = _timed(mesh_compiled, Compiled(shelled(nm, curved), similar=similar), 24)
        out["mesh"][name] = {"counts": [nm, nm, nm], "segments": 24, "seconds": secs, "triangles": len(mesh.faces),
                             "volume": float(mesh.volume), "watertight": bool(mesh.is_watertight)}
    return out
