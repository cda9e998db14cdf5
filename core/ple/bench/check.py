"""Unclean-pair search on a 10⁶-beam lattice: the steady path (anchors + RangeFinder) vs a KD-tree over
sampled beam points, in the same run; and the exact self-intersection check of meshes
(``ple.meshing.selfcheck``): compiled vs numpy, each in a fresh process on the same mesh (seconds,
CPU seconds, triangles per CPU second, peak memory), and ``ple mesh --check`` on the README's octet.

The lattice: an n³ cubic lattice (axis struts) with both face diagonals of every xy face, which
cross at the face centre (unclean by construction: (n−1)² n beam–beam pairs). The baseline samples
``--samples`` points along every beam axis (away from the end balls), finds point pairs closer than
2 r + the sample spacing with ``scipy.spatial.cKDTree`` (every overlapping pair of equal-radius
beams has such a pair), then tests the distinct non-incident beam pairs exactly. Both report the
same counts (checked)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from ..algebra.similarity import Translation
from ..io.export import export_mesh, read_back
from ..meshing.tessellate import tessellate
from ..model.lattice import Lattice
from ..program.sources import load_lattice
from ..queries.overlaps import KINDS, pair_gaps, unclean_pairs


def add_arguments(p) -> None:
    p.add_argument("--n", type=int, default=60, help="groups per direction (default 60: about 10⁶ beams)")
    p.add_argument("--radius", type=float, default=0.08, help="ball radius (default 0.08)")
    p.add_argument("--samples", type=int, default=3, help="baseline sample points per beam (default 3)")
    p.add_argument("--no-baseline", action="store_true", help="skip the KD-tree baseline")
    p.add_argument("--selfcheck", choices=("both", "compiled", "none"), default="both",
                   help="self-intersection check rows: compiled and numpy (default), compiled only, none")


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
    if args.selfcheck != "none":
        out["selfcheck"] = selfcheck_rows(args.selfcheck == "both")
    return out


# the child resets its peak resident size (Linux: /proc/self/clear_refs) after loading the mesh, so
# the peak is the check's own: extra_peak_gb is that peak above the resident size before the check
SELFCHECK_CHILD = """
import json, sys, time
import numpy as np
from ple.meshing import selfcheck
if sys.argv[2] == "numpy":
    selfcheck._compiled = None
with np.load(sys.argv[1]) as z:
    v, f = z["vertices"], z["faces"]
def status(key):
    with open("/proc/self/status") as fh:
        return next(int(line.split()[1]) * 1024 for line in fh if line.startswith(key))
with open("/proc/self/clear_refs", "w") as fh:
    fh.write("5")
before = status("VmRSS:")
t0, c0 = time.perf_counter(), time.process_time()
pairs = selfcheck.self_intersections(v, f)
print(json.dumps({"seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0, "pairs": len(pairs),
                  "extra_peak_gb": (status("VmHWM:") - before) / 1e9}))
"""


def _meshes():
    """(name, what, vertices, faces): the README's octet (refined, 337 k triangles, the file
    ``ple mesh --check`` reads back) and a union result (an unclean lattice of crossing face
    diagonals, meshed with manifold3d unions and moved onto the float32 grid)."""
    with tempfile.TemporaryDirectory() as d:
        export_mesh(tessellate(load_lattice("octet", ["n=2"]), style="refined"), os.path.join(d, "o.stl"))
        octet = read_back(os.path.join(d, "o.stl"))
    yield "octet", "octet n=2, refined, read back from STL", octet.vertices, octet.faces
    union = tessellate(lattice(4, 0.08), style="refined", levels=3)
    what = "crossing face diagonals 4³ (36 unclean pairs), refined 3 levels, united"
    yield "union", what, union.vertices, union.faces


def selfcheck_rows(numpy_too: bool = True) -> dict:
    """Each mesh checked by the compiled and the numpy form, each in a fresh process."""
    rows = {}
    with tempfile.TemporaryDirectory() as d:
        for name, what, v, f in _meshes():
            path = os.path.join(d, f"{name}.npz")
            np.savez(path, vertices=np.asarray(v, float), faces=np.asarray(f, np.int64))
            row = {"mesh": what, "triangles": int(len(f))}
            for form in ("compiled", "numpy") if numpy_too else ("compiled",):
                run = subprocess.run([sys.executable, "-c", SELFCHECK_CHILD, path, form], capture_output=True,
                                     text=True, check=True)
                r = json.loads(run.stdout)
                r["triangles_per_cpu_second"] = round(len(f) / max(r["cpu_seconds"], 1e-9))
                row[form] = {k: round(x, 3) if isinstance(x, float) else x for k, x in r.items()}
            if numpy_too:
                row["cpu_speedup"] = round(row["numpy"]["cpu_seconds"] / max(row["compiled"]["cpu_seconds"], 1e-9), 1)
                row["agree"] = row["numpy"]["pairs"] == row["compiled"]["pairs"]
            rows[name] = row
    rows["load_average"] = [round(x, 2) for x in os.getloadavg()]
    return rows


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
