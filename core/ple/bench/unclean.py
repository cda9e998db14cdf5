"""Unclean lattices to binary STL, each beside one manifold3d batch union of the same elements.

``ple mesh``'s own path, beside one manifold3d batch union of the same balls and cone-beams.

Cases (what users print: thick, dense, curved):

- ``fig6_3``: thesis Fig. 6.3 with its defaults (refined, 4 levels); its short beams pull
  contact circles in from S⁺ (``achocc.pulled_circles``);
- ``curved``: a curved n³ lattice, one ball of radius 0.12, beams (1,0,0), (0,1,0), (0,0,1),
  (1,1,0), V a rotation about a far axis, W a swirl that makes W-beams about 0.42 long: every
  hub's S⁺ passes the far end of its W beams;
- ``crossing``: crossing diagonals (1,1,0) and (-1,1,0) on curved rows, n³ (8 and 30): every
  pair of diagonals crosses, each crossing is a local union (``ple.meshing.unions``);
- ``tenth``: a cubic n³ lattice (10⁶ beams at n = 70) with a tenth of its hubs, chosen at random,
  treated as unclean (balls and cone-beams united locally, the rest on the fast path).

Each case runs in a fresh process (wall and CPU seconds, peak resident memory, triangles, the
estimate our budget checks); the baseline is one ``Manifold.batch_boolean`` of every ball
(``unclean.ball_segments`` of ours, ``--segments``) and every cone-beam (``batch_hull`` of its two balls), in a fresh
process too, stopped after ``--union-timeout`` seconds (reported as a lower bound). The thick
cases also stand beside manifold3d's ``level_set`` of the exact solid (``ple.bench._level_set``: the
edge length calibrated to 1 % volume on a corner block, its volume against the union's), stopped
after the same time.
"""

from __future__ import annotations

import itertools
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from ..algebra.similarity import Rotation, Scaling, Screw, Swirl, Translation
from ..algebra.vectors import Pt, Vec
from ..io.export import RecordPool, stl_chunk, stl_header, write_stl
from ..io.irfile import save_ir
from ..meshing.tessellate import (
    BOX_TRIANGLES,
    Tessellator,
    check_bytes,
    iter_triangles,
    leave_to_unions,
    merged,
    resolve_style,
    union_pieces,
)
from ..meshing.unclean import UncleanReport, ball_segments
from ..meshing.weld import grid_spacing
from ..model.budget import MESH_TRIANGLE_BYTES, evaluation_bytes, mesh_triangles
from ..model.lattice import Lattice, Region
from ..program.sources import load_lattice
from ._level_set import unit_deficit

CHILD = r"""
import json, os, resource, sys, time
import numpy as np
from ple.bench.unclean import case_lattice
name, n, style, levels, out = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), sys.argv[5]
segments = int(sys.argv[6]) or None  # of the mesh (0: the style's default); its unions' balls: ball_segments
lat = case_lattice(name, n)
import ple.meshing.tessellate, ple.app.pipeline, manifold3d  # the process's own baseline, before any work
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1e3
t0, c0 = time.perf_counter(), time.process_time()
if name == "tenth":
    from ple.bench.unclean import write_tenth
    tris, report, estimate = write_tenth(lat, out, style, levels, segments=segments)
else:
    from ple.app.pipeline import MeshRequest, write_mesh
    from ple.bench.unclean import stream_estimate
    info = {}
    from ple.model.budget import default_max_memory
    tris = write_mesh(MeshRequest(lat, style=style, levels=levels, segments=segments, max_memory=default_max_memory()),
                      out, info=info)
    report = info["unclean"]
    estimate = stream_estimate(lat, style, levels, report, segments)
estimate += base
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
ru, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
peak = max(ru.ru_maxrss, kids.ru_maxrss)  # the unions run in forked children (unions.stoppable)
print(json.dumps({"triangles": int(tris), "seconds": wall, "cpu_seconds": cpu + kids.ru_utime,
    "peak_rss_gb": peak / 1e6, "estimate_gb": estimate / 1e9,
    "groups": lat.groups, "beams": lat.beam_count(), "unclean": None if report is None else report.line()}))
"""

UNION = r"""
import json, resource, sys, time
import manifold3d
from ple.bench.unclean import case_lattice
from ple.meshing.unclean import SPHERE_SEGMENTS
lat = case_lattice(sys.argv[1], int(sys.argv[2]))
t0, c0 = time.perf_counter(), time.process_time()
from ple.model.lattice import Region
m = int(sys.argv[3]) if len(sys.argv) > 3 else 0  # a corner block of m³ groups only (0: the whole lattice)
segments = int(sys.argv[4]) if len(sys.argv) > 4 else SPHERE_SEGMENTS  # of every ball (and so of every hull)
ev = lat.evaluate(Region(0, m, 0, m, 0, m) if m else lat.region())
from ple.bench._level_set import element_union
u = element_union(ev.center, ev.radius, ev.beam_nodes, segments)
tris = u.num_tri()
print(json.dumps({"triangles": int(tris), "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0,
                  "volume": float(u.volume()),
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
"""

LEVEL_SET = r"""
import json, resource, sys, time
from ple.bench._level_set import calibrated_edge, level_set_mesh
from ple.bench.unclean import case_lattice
from ple.model.lattice import Region
lat = case_lattice(sys.argv[1], int(sys.argv[2]))
t0, c0 = time.perf_counter(), time.process_time()
cal = calibrated_edge(lat.evaluate(Region(0, 2, 0, 2, 0, 2)))  # on the corner block of 2^3 groups
t1, c1 = time.perf_counter(), time.process_time()
ev = lat.evaluate(lat.region())
m = level_set_mesh(ev.center, ev.radius, ev.beam_nodes, cal["edge"])
tris = m.num_tri()
print(json.dumps({"triangles": int(tris), "volume": float(m.volume()), "edge": cal["edge"],
                  "calibration": cal, "calibration_seconds": t1 - t0, "seconds": time.perf_counter() - t1,
                  "cpu_seconds": time.process_time() - c1,
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
"""

CASES = [("fig6_3", 0, "refined", 4), ("curved", 40, "cnt", 0), ("curved", 40, "refined", 2),
         ("crossing", 8, "cnt", 0), ("crossing", 8, "refined", 4), ("crossing", 30, "cnt", 0),
         ("tenth", 70, "cnt", 0),
         # thick: every hub unclean, one cluster with no free beam, meshed in slabs (ple.meshing.slabs); each
         # at a size one union still finishes and at about 10x its groups
         ("thick_octet", 8, "cnt", 0), ("thick_octet", 17, "cnt", 0), ("thick_octet", 8, "refined", 3),
         ("shrunk_graded", 10, "cnt", 0), ("shrunk_graded", 22, "cnt", 0),
         ("thick_bcc_screw", 6, "cnt", 0), ("thick_bcc_screw", 12, "cnt", 0), ("thick_bcc_screw", 6, "refined", 3)]


THICK = ("thick_octet", "shrunk_graded", "thick_bcc_screw")  # every hub unclean: beside a level set too


def add_arguments(p) -> None:
    p.add_argument("--cases", default="all",
                   help="comma-separated case names (fig6_3, curved, crossing, tenth, thick_octet, shrunk_graded, "
                        "thick_bcc_screw) or all (default)")
    p.add_argument("--union-timeout", type=float, default=600.0,
                   help="seconds after which the manifold3d baseline is stopped (default 600)")
    p.add_argument("--union-memory", type=float, default=12.0,
                   help="GB of address space the manifold3d baseline may take before it is stopped (default 12: "
                        "half this machine; the speed-up is then a lower bound)")
    p.add_argument("--union-segments", default="",
                   help="comma-separated segment counts (e.g. 16) of further manifold3d baselines, beside the one "
                        "at our unions' ball segments; rows get manifold3d_union_<s>, wall_speedup_<s>")
    p.add_argument("--segments", type=int, default=0,
                   help="segments of our meshes (default: the style's, 16); our unions' balls and the baseline's "
                        "take unclean.ball_segments of it (at least 32)")
    p.add_argument("--no-level-set", action="store_true",
                   help="skip the manifold3d level_set baseline of the thick cases (at the edge length that puts a "
                        "corner block's volume within 1 %%, ple.bench._level_set; stopped after --union-timeout)")
    p.add_argument("--scale", type=float, default=100.0,
                   help="every case's n in percent of its size (default 100: the issue's sizes)")
    p.add_argument("--verify", action="store_true",
                   help="also mesh every case with `ple mesh CASE.json --check` (not timed): watertight, exact "
                        "self-intersections, and the volume against a Monte Carlo estimate of the union with its σ")


def case_lattice(name: str, n: int):
    """The lattice of a case (module docstring)."""
    if name == "fig6_3":
        return load_lattice("fig6_3")
    lat = Lattice()
    if name == "curved":
        a = lat.add_node(Pt(0, 0, 0), 0.12)
        for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
            lat.add_beam(a, a, *off)
        lat.set_u(n, Translation(Vec(1, 0, 0)))
        lat.set_v(n, Rotation(0.02, Vec(0, 0, 1), Pt(-45, 0, 0)))
        lat.set_w(n, Swirl(0.0025, Vec(0, 1, 0), Pt(160, 0, 0), 0.999))
    elif name == "crossing":
        a = lat.add_node(Pt(0, 0, 0), 0.1)
        for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0)]:
            lat.add_beam(a, a, *off)
        lat.set_u(n, Translation(Vec(1, 0, 0)))
        lat.set_v(n, Rotation(0.02, Vec(0, 0, 1), Pt(-45, 0, 0)))
        lat.set_w(n, Translation(Vec(0, 0, 1)))
    elif name == "tenth":
        a = lat.add_node(Pt(0, 0, 0), 0.1)
        for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
            lat.add_beam(a, a, *off)
        for s, v in (("u", Vec(1, 0, 0)), ("v", Vec(0, 1, 0)), ("w", Vec(0, 0, 1))):
            getattr(lat, f"set_{s}")(n, Translation(v))
    elif name == "thick_octet":  # the axes and six face diagonals on rows curved about an axis 16 cells away; at
        # r 0.16 these rows' clusters are pairs of crossing diagonals, at 0.2 every hub shrinks into one cluster
        a = lat.add_node(Pt(0, 0, 0), 0.2)
        for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0), (1, 0, 1), (-1, 0, 1), (0, 1, 1),
                    (0, -1, 1)]:
            lat.add_beam(a, a, *off)
        lat.set_u(n, Translation(Vec(1, 0, 0)))
        lat.set_v(n, Rotation(0.06, Vec(0, 0, 1), Pt(-16, 0, 0)))
        lat.set_w(max(2, n // 2), Translation(Vec(0, 0, 1)))
    elif name == "shrunk_graded":  # two balls 0.2 apart, beams shorter than their junctions, U a scaling of 1.025
        a = lat.add_node(Pt(0, 0, 0), 0.13)
        b = lat.add_node(Pt(0.1, 0.17, 0.03), 0.13)
        lat.add_beam(a, b, 0, 0, 0)
        lat.add_beam(b, a, 1, 0, 0)
        lat.add_beam(b, a, 0, 1, 0)
        lat.add_beam(a, a, 0, 0, 1)
        lat.add_beam(b, b, 0, 0, 1)
        lat.set_u(n, Scaling(1.025, Pt(-20, 0, 0)))
        lat.set_v(n, Translation(Vec(0, 0.5, 0)))
        lat.set_w(max(2, round(n * 10 / 22)), Translation(Vec(0, 0, 0.5)))
    elif name == "thick_bcc_screw":  # balls r 0.15 at the corner and centre; cubic edges, body diagonals, a face one
        a = lat.add_node(Pt(0, 0, 0), 0.15)
        c = lat.add_node(Pt(0.5, 0.5, 0.5), 0.15)
        for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
            lat.add_beam(a, a, *off)
        for off in itertools.product((0, 1), repeat=3):
            lat.add_beam(c, a, *off)
        lat.set_u(n, Translation(Vec(1, 0, 0)))
        lat.set_v(n, Translation(Vec(0, 1, 0)))
        lat.set_w(n, Screw(0.03, Vec(0, 0, 1), Pt(n / 2, n / 2, 0), 1.0))
    else:
        raise ValueError(name)
    return lat


def write_tenth(lat, out, style: str, levels: int, fraction: float = 0.1, seed: int = 0, segments=None):
    """The ``tenth`` case: a random tenth of the hubs unclean (as if their junctions had shrunk),
    streamed to binary STL as ``ple mesh`` streams an unclean region. Returns (triangles, report,
    estimated peak bytes)."""
    r = lat.region()
    lv, sg = resolve_style(style, levels, segments)
    grid = grid_spacing(*lat.bounds(r))
    tess = Tessellator(lat, r, style, lv, sg, grid=grid)
    ev = lat.evaluate(r)
    rng = np.random.default_rng(seed)
    nodes = np.sort(rng.choice(len(ev.center), int(round(fraction * len(ev.center))), replace=False))
    shrunk = np.zeros(len(ev.center), bool)
    shrunk[nodes] = True
    report = UncleanReport(nodes, 0, len(nodes), 0, 0, np.zeros((0, 2), np.int64), shrunk)
    cl = leave_to_unions(tess, ev, report)
    pool = RecordPool()
    encode = lambda chunk: stl_chunk(chunk, grid, pool)  # noqa: E731
    chunks = [map(encode, merged(union_pieces(tess, ev, cl, report))),
              iter_triangles(lat, r, style, lv, sg, _tess=tess, encode=encode)]
    tris = write_stl(out, itertools.chain(*chunks), header=stl_header("mm"), pool=pool)
    return tris, report, stream_estimate(lat, style, levels, report, segments)


def stream_estimate(lat, style: str, levels: int, report, segments=None) -> float:
    """Peak bytes of streaming a region to STL beyond the process's own: its evaluation (the
    cleanliness check holds it), the boxes alive at once (two, each at most BOX_TRIANGLES) and the
    largest local union (``unions.piece_estimate``); the check's own peak includes the evaluation."""
    r = lat.region()
    lv, sg = resolve_style(style, levels, segments)
    box = min(mesh_triangles(lat, r, style, lv, sg), BOX_TRIANGLES) * MESH_TRIANGLE_BYTES
    return (max(evaluation_bytes(lat, r), check_bytes(lat, r)) + 2 * box
            + (report.union_bytes if report is not None else 0))


def _run(code: str, args: list, timeout: float | None = None, memory: float | None = None) -> dict:
    """``code`` in a fresh Python process; its JSON line, or why there is none. ``memory``: bytes
    of address space the process may take (``RLIMIT_AS``): a baseline that would take more than
    the machine has is stopped there, with the CPU seconds it had spent (a lower bound)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()  # the process's wall time, start-up and imports included, is what a user waits
    limit = None if memory is None else (lambda: resource.setrlimit(resource.RLIMIT_AS, (int(memory), int(memory))))
    try:
        proc = subprocess.run([sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True,
                              timeout=timeout, preexec_fn=limit)
    except subprocess.TimeoutExpired:
        return {"timeout": timeout}
    if proc.returncode:
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        out = {"error": (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[-1]}
        if memory is not None:
            cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
            out.update({"memory_limit_gb": memory / 1e9, "seconds_until_stopped": time.perf_counter() - t0,
                        "cpu_seconds_until_stopped": cpu})
        return out
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    out["process_wall_seconds"] = time.perf_counter() - t0
    out["process_cpu_seconds"] = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return out


def _verify(ir: str, style: str, levels: int, out: str) -> dict:
    """``ple mesh IR --check`` of a case, as a user runs it: its report (``cli.mesh.check_report``)."""
    cmd = [sys.executable, "-m", "ple.cli", "mesh", ir, "--style", style, "--out", out, "--check"]
    proc = subprocess.run(cmd + (["--levels", str(levels)] if style == "refined" else []), capture_output=True,
                          text=True)
    text = proc.stdout
    if proc.returncode or "{" not in text:
        return {"error": (proc.stderr.strip().splitlines() or [f"exit {proc.returncode}"])[-1]}
    rep = json.loads(text[text.index("\n{") + 1:] if "\n{" in text else text[text.index("{"):])
    keep = ("triangles", "watertight", "winding_consistent", "self_intersecting_pairs", "mesh_volume",
            "lattice_volume", "lattice_volume_source", "relative_volume_error")
    return {k: rep[k] for k in keep if k in rep}


def _block_union(name: str, n: int, args) -> dict:
    """For a union stopped before its end: the union of the lattice's corner block of about a
    third of its groups along each index, measured, and scaled by the ratio of elements (balls
    and beams): a union's work grows at least linearly with its elements, so the scaled time is
    a lower bound of the whole union's (never an estimate from above)."""
    m = max(2, n // 3)
    got = _run(UNION, [name, n, m, ball_segments(args.segments or None)], args.union_timeout, args.union_memory * 1e9)
    if "cpu_seconds" not in got:
        return {"block": m, "block_union": got}
    lat = case_lattice(name, n)
    whole, block = lat.evaluate(lat.region()), lat.evaluate(Region(0, m, 0, m, 0, m))
    ratio = (len(whole.center) + len(whole.beam_nodes)) / (len(block.center) + len(block.beam_nodes))
    return {"block": m, "block_cpu_seconds": got["cpu_seconds"], "block_peak_rss_gb": got["peak_rss_gb"],
            "elements_ratio": ratio, "block_cpu_seconds_scaled": got["cpu_seconds"] * ratio}


def run(args) -> dict:
    wanted = None if args.cases == "all" else set(args.cases.split(","))
    rows, level_sets = [], {}
    with tempfile.TemporaryDirectory(prefix="ple-bench-unclean-") as d:
        for name, n, style, levels in CASES:
            if wanted is not None and name not in wanted:
                continue
            n = max(2, int(round(n * args.scale / 100))) if n else 0
            ours = _run(CHILD, [name, n, style, levels, os.path.join(d, "o.stl"), args.segments or 0])
            balls = ball_segments(args.segments or None)  # our unions' balls, and so the baseline's
            row = {"case": name, "n": n, "style": style, "levels": levels, "segments": args.segments or None,
                   "ball_segments": balls, "ours": ours}
            if "seconds" in ours:
                ours["triangles_per_s"] = ours["triangles"] / max(ours["seconds"], 1e-9)
                ours["peak_over_estimate"] = ours["peak_rss_gb"] / max(ours["estimate_gb"], 1e-9)
            base = _run(UNION, [name, n, 0, balls], args.union_timeout, args.union_memory * 1e9)
            row["manifold3d_union"] = base
            if "cpu_seconds" not in base and n:
                base.update(_block_union(name, n, args))
            if "seconds" in ours:
                t = base.get("cpu_seconds", max(base.get("timeout", 0.0), base.get("cpu_seconds_until_stopped", 0.0),
                                                base.get("block_cpu_seconds_scaled", 0.0)))
                row["cpu_speedup"] = t / max(ours["cpu_seconds"], 1e-9)
                row["speedup_is_lower_bound"] = "cpu_seconds" not in base
                if "process_wall_seconds" in base:  # both processes' wall time, start-up included
                    row["wall_speedup"] = base["process_wall_seconds"] / max(ours["process_wall_seconds"], 1e-9)
            if name in THICK and not args.no_level_set:  # one per lattice (its styles' rows share it)
                if (name, n) not in level_sets:
                    level_sets[name, n] = ls = _run(LEVEL_SET, [name, n], args.union_timeout, args.union_memory * 1e9)
                    if "volume" in ls and "volume" in base:
                        ls["volume_vs_union"] = ls["volume"] / base["volume"] - 1.0
                        # against the exact solid, as far as the union tells it: its polygonal balls
                        # hold unit_deficit of the exact balls' volume (2.2 % under at 32 segments)
                        ls["volume_vs_exact"] = ls["volume"] * unit_deficit(balls) / base["volume"] - 1.0
                    if "process_wall_seconds" in ls:  # what meshing waits: the edge's calibration left out
                        ls["process_wall_seconds"] -= ls["calibration_seconds"]
                row["manifold3d_level_set"] = ls = level_sets[name, n]
                if "process_wall_seconds" in ls and "process_wall_seconds" in ours:
                    row["wall_speedup_level_set"] = ls["process_wall_seconds"] / max(ours["process_wall_seconds"], 1e-9)
            if args.verify and name != "tenth":  # tenth's unclean hubs are chosen, not found: not ple mesh's file
                save_ir(case_lattice(name, n), os.path.join(d, "case.json"))
                row["verify"] = _verify(os.path.join(d, "case.json"), style, levels, os.path.join(d, "v.stl"))
            for seg in [int(x) for x in args.union_segments.split(",") if x.strip()]:
                other = _run(UNION, [name, n, 0, seg], args.union_timeout, args.union_memory * 1e9)
                row[f"manifold3d_union_{seg}"] = other
                if "process_wall_seconds" in other and "process_wall_seconds" in ours:
                    row[f"wall_speedup_{seg}"] = other["process_wall_seconds"] / max(ours["process_wall_seconds"], 1e-9)
            rows.append(row)
            print(json.dumps(row), file=sys.stderr, flush=True)
    return {"benchmark": "unclean", "machine": f"{os.cpu_count()} cores", "union_timeout_s": args.union_timeout,
            "union_memory_gb": args.union_memory, "rows": rows}
