"""Meshing throughput: triangles per second to binary STL, a 10⁶-beam lattice meshed in a
subprocess (wall time, peak memory), and the same lattice's 10³-group region against the
alternative a user would pick — a union of ball and beam meshes with manifold3d."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import trimesh

from ..errors import PleError
from ..io.export import write_stl
from ..meshing.tessellate import Tessellator, build_with_unions, tessellate
from ..meshing.unclean import UncleanReport
from ..program.sources import load_lattice
from ._timing import best_of
from .curved import rows as lattice_rows
from .startup import startup_rows

CHILD = """
import json, resource, sys, time
from ple.program.sources import load_lattice
from ple.app.pipeline import MeshRequest, write_mesh
lat = load_lattice(sys.argv[1]).with_counts(*[int(x) for x in sys.argv[2].split(",")])
t0 = time.perf_counter()
n = write_mesh(MeshRequest(lat, style=sys.argv[4]), sys.argv[3])
dt = time.perf_counter() - t0
print(json.dumps({"beams": lat.beam_count(), "groups": lat.groups, "triangles": n, "seconds": dt,
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
"""


def add_arguments(p) -> None:
    p.add_argument("--lattice", default="cubic", help="preset or file (default: cubic)")
    p.add_argument("--big", type=int, default=70, help="n for the n³ lattice of the 10⁶-beam run (default 70)")
    p.add_argument("--style", default="cnt", help="style of the big run (default cnt)")
    p.add_argument("--region", type=int, default=10, help="n for the n³-group manifold3d comparison (default 10)")
    p.add_argument("--curved", type=int, default=40, help="n of the curved and regular n³ rows (default 40; 0 skips)")
    p.add_argument("--warped", type=int, default=70, help="n of the warped n³ row (default 70: 10⁶ beams; 0 skips)")
    p.add_argument("--levels", type=int, default=2, help="refinement levels of the refined rows (default 2)")
    p.add_argument("--no-per-hub", action="store_true", help="skip the per-hub baseline rows (slow)")


def _stl_rate(lat) -> dict:
    """Our writer (from vertices and faces, as the tessellator streams them) against trimesh's
    binary STL export of a fresh mesh (so its normals are computed, not cached), interleaved."""
    mesh = tessellate(lat.with_counts(30, 30, 30), style="cnt")
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    ours, base = float("inf"), float("inf")
    with tempfile.TemporaryDirectory() as d:
        def trimesh_stl():
            with open(os.path.join(d, "b.stl"), "wb") as fh:
                fh.write(trimesh.Trimesh(v, f, process=False).export(file_type="stl"))

        for _ in range(3):
            ours = min(ours, best_of(lambda: write_stl(os.path.join(d, "a.stl"), [(v, f)]), repeat=1))
            base = min(base, best_of(trimesh_stl, repeat=1))
    return {"triangles": len(f), "ple_s": ours, "ple_triangles_per_s": len(f) / ours,
            "baseline_trimesh_export_s": base, "baseline_triangles_per_s": len(f) / base}


def _big(name: str, n: int, style: str) -> dict:
    with tempfile.TemporaryDirectory() as d:
        out = subprocess.run([sys.executable, "-c", CHILD, name, f"{n},{n},{n}", os.path.join(d, "big.stl"), style],
                             capture_output=True, text=True, check=True)
    row = json.loads(out.stdout.strip().splitlines()[-1])
    row["style"] = style
    row["triangles_per_s"] = row["triangles"] / row["seconds"]
    return row


def _manifold_union(lat, segments: int = 16) -> tuple[float, float, int]:
    """Time of the user's alternative: a sphere per ball and a frustum per beam, unioned."""
    import manifold3d as m3d

    ev = lat.evaluate()
    t0 = time.perf_counter()
    parts = [m3d.Manifold.sphere(float(r), segments).translate(tuple(c)) for c, r in zip(ev.center, ev.radius)]
    for i, j in ev.beam_nodes:
        a, b = ev.center[i], ev.center[j]
        d = b - a
        length = float(np.linalg.norm(d))
        z = d / length
        x = np.cross(z, [1.0, 0, 0] if abs(z[0]) < 0.9 else [0, 1.0, 0])
        x /= np.linalg.norm(x)
        frame = np.column_stack([x, np.cross(z, x), z, a])
        cyl = m3d.Manifold.cylinder(length, float(ev.radius[i]), float(ev.radius[j]), segments)
        parts.append(cyl.transform(frame.tolist()))
    union = m3d.Manifold.batch_boolean(parts, m3d.OpType.Add)
    mesh = union.to_mesh()
    return time.perf_counter() - t0, float(union.volume()), len(mesh.tri_verts)


def _unclean_cost(region, fraction: float = 0.1, seed: int = 0) -> dict:
    """Throughput of the fast path on a clean lattice (with and without the cleanliness check)
    and with ``fraction`` of its hubs treated as unclean (fast path for the rest, manifold3d
    unions for those), per style; the union of everything is ``_manifold_union``'s row."""
    r = region.region()
    out = {}
    for style in ("cnt", "chocc"):
        t0 = time.perf_counter()
        fast = tessellate(region, style=style, check_clean=False)
        t1 = time.perf_counter()
        checked = tessellate(region, style=style)
        t2 = time.perf_counter()
        tess = Tessellator(region, r, style, 4, 16)
        t_d = time.perf_counter()
        rep, ev = tess.find_unclean()
        detector = time.perf_counter() - t_d  # what a clean lattice pays for the check (templates shared)
        rng = np.random.default_rng(seed)
        nodes = np.sort(rng.choice(len(ev.center), int(round(fraction * len(ev.center))), replace=False))
        shrunk = np.zeros(len(ev.center), bool)
        shrunk[nodes] = True  # as if their junctions had to shrink: balls and cone-beams, united locally
        v, f = build_with_unions(tess, ev, UncleanReport(nodes, 0, len(nodes), 0, 0, np.zeros((0, 2), np.int64),
                                                         shrunk))
        t3 = time.perf_counter()
        mesh = trimesh.Trimesh(v, f, process=False)
        out[style] = {"clean_unchecked_s": t1 - t0, "clean_checked_s": t2 - t1, "detector_s": detector,
                      "detector_found": int(len(rep.nodes)),
                      "clean_unclean_hubs_found": int(len(checked.metadata["ple_unclean"].nodes)),
                      "clean_triangles": len(fast.faces), "clean_triangles_per_s": len(fast.faces) / (t2 - t1),
                      f"unclean_{int(fraction * 100)}pct_s": t3 - t2, "unclean_hubs": int(len(nodes)),
                      "unclean_triangles": len(f), "unclean_triangles_per_s": len(f) / (t3 - t2),
                      "unclean_watertight": bool(mesh.is_watertight), "unclean_volume": float(mesh.volume)}
    return out


def run(args) -> dict:
    for flag, n in (("--big", args.big), ("--region", args.region)):
        if not 2 <= n <= 1000:
            raise PleError(f"{flag} {n}: expected 2..1000")
    for flag, n in (("--curved", args.curved), ("--warped", args.warped)):
        if n and not 2 <= n <= 200:
            raise PleError(f"{flag} {n}: expected 0 (skip) or 2..200")
    if not 0 <= args.levels <= 4:
        raise PleError(f"--levels {args.levels}: expected 0..4")
    load = list(os.getloadavg())
    lat = load_lattice(args.lattice)
    big = _big(args.lattice, args.big, args.style)  # first: a forked child starts with its parent's RSS
    region = lat.with_counts(args.region, args.region, args.region)
    tessellate(lat.with_counts(2, 2, 2), style="cnt")  # warm-up: imports and first calls
    ours = {}
    for style in ("cnt", "chocc", "refined"):
        t0 = time.perf_counter()
        mesh = tessellate(region, style=style)
        ours[style] = {"seconds": time.perf_counter() - t0, "triangles": len(mesh.faces),
                       "volume": float(mesh.volume), "watertight": bool(mesh.is_watertight)}
    m_time, m_vol, m_tri = _manifold_union(region)
    unclean = _unclean_cost(region)
    # issue 14's table: regular, curved and warped lattices per style, per-hub baseline, writer alone
    lattices = lattice_rows(args.curved, args.warped, ["cnt", "refined"], args.levels, not args.no_per_hub) \
        if args.curved else []
    return {"benchmark": "mesh", "lattice": args.lattice, "machine": f"{os.cpu_count()} cores",
            "load_average_at_start": load, "startup": startup_rows(10), "lattices": lattices,
            "stl_write": _stl_rate(lat),
            "big_lattice": big,
            "region_vs_manifold3d": {"groups": region.groups, "beams": region.beam_count(), "ple": ours,
                                     "baseline_manifold3d_union": {"seconds": m_time, "volume": m_vol,
                                                                   "triangles": m_tri},
                                     "speedup_cnt": m_time / ours["cnt"]["seconds"],
                                     "speedup_chocc": m_time / ours["chocc"]["seconds"],
                                     "speedup_refined": m_time / ours["refined"]["seconds"]},
            "clean_vs_unclean": {"groups": region.groups, "ple": unclean,
                                 "baseline_manifold3d_union_s": m_time}}
