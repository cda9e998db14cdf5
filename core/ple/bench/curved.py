"""Meshing throughput of regular, curved and warped lattices to binary STL (issue 14): batched
hub templates against the per-hub path in the same run, 1 vs 2 workers, the STL writer alone.

Lattices:
- ``curved`` n³: translation U, rotation V (about z), swirl W, one ball and 4 beam-patterns —
  every (i, j) column has its own hub shape (issue 14's 40³ lattice);
- ``regular`` n³: the same beams on translations (one hub shape per boundary case);
- ``warped`` n³: the ``warped`` preset (bent U, screwed V, tapered W; 10⁶ beams at n = 70).

Each row streams the whole lattice to a binary STL in a child process of its own (so its peak
memory, VmHWM, is its own): ``iter_triangles`` + ``write_stl`` with the float32 snap — the path
``ple mesh`` takes once the cleanliness check has passed (the check is timed separately:
``check_s`` and the unclean hubs it finds; a lattice with unclean hubs needs unions, see
``ple bench mesh``'s clean_vs_unclean). ``stl_writer_only`` times the writer alone on the same
boxes, one at a time on one thread, the tessellation between them not timed (the ceiling on
this machine)."""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from ..algebra.similarity import Rotation, Swirl, Translation
from ..app.pipeline import MeshRequest, write_mesh
from ..errors import PleError, echo
from ..io.export import RecordPool, StlWriter, direct_writer, stl_chunk, stl_header, write_stl
from ..meshing.tessellate import Tessellator, iter_triangles, output_grid
from ..model.lattice import Lattice
from ..program.sources import load_lattice

CHILD = """
import json, sys
from ple.bench.curved import child_row
print(json.dumps(child_row(*json.loads(sys.argv[1]))))
"""


def add_arguments(p) -> None:
    p.add_argument("--n", type=int, default=40, help="the n³ curved and regular lattices (default 40, the issue's)")
    p.add_argument("--warped-n", type=int, default=70, help="the n³ warped lattice (default 70: 10⁶ beams; 0 skips)")
    p.add_argument("--levels", type=int, default=2, help="refinement levels of the refined rows (default 2)")
    p.add_argument("--styles", default="cnt,refined", help="comma-separated styles (default cnt,refined)")
    p.add_argument("--no-per-hub", action="store_true", help="skip the per-hub baseline rows (slow)")
    p.add_argument("--repeat", type=int, default=3, help="runs of each batched row, the fastest kept (default 3)")


def curved_lattice(n: int, radius: float = 0.08) -> Lattice:
    """Translation U, rotation V about z, swirl W (rotation about y with a slight shrink). At
    n = 40 the rows turn by 46° (V) and 13° (W): 4,800 distinct hub shapes, and clean (no unclean
    hub: ``ple mesh`` streams it). The sharper first version (V 0.03 rad about x = -30, W
    0.008 rad about x = 120) stretched V-beams to 2.1 and shrank W-beams to 0.64 at the far rows:
    6 % of its hubs were unclean there, and ``ple mesh`` unites those exactly, in memory
    (issue 13) — not the streamed path this benchmark is about."""
    lat = Lattice()
    a = lat.add_node((0.0, 0.0, 0.0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation((1.0, 0.0, 0.0)))
    lat.set_v(n, Rotation(0.02, (0.0, 0.0, 1.0), (-45.0, 0.0, 0.0)))
    lat.set_w(n, Swirl(0.006, (0.0, 1.0, 0.0), (160.0, 0.0, 0.0), 0.998))
    return lat


def regular_lattice(n: int, radius: float = 0.08) -> Lattice:
    lat = Lattice()
    a = lat.add_node((0.0, 0.0, 0.0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation((1.0, 0.0, 0.0)))
    lat.set_v(n, Translation((0.0, 1.0, 0.0)))
    lat.set_w(n, Translation((0.0, 0.0, 1.0)))
    return lat


def bench_lattice(name: str, n: int) -> Lattice:
    if name == "curved":
        return curved_lattice(n)
    if name == "regular":
        return regular_lattice(n)
    if name == "warped":
        return load_lattice("warped", {"n": n})
    raise PleError(f"unknown bench lattice {echo(name)}")


def _stream(lat: Lattice, style: str, levels: int, batched: bool, workers: int, path: str | None) -> dict:
    """The checked stream of ``ple mesh``: each box encoded by the thread that assembled it, into
    record buffers handed on from written boxes. ``path`` None: the records are counted, not
    written (the computation without the file system)."""
    r = lat.region()
    t0 = time.perf_counter()
    tess = Tessellator(lat, r, style, levels, 16, batched=batched, workers=workers)
    grid, pool = output_grid(lat, r), RecordPool()
    chunks = iter_triangles(lat, r, style, levels, _tess=tess, workers=workers,
                            encode=lambda chunk: stl_chunk(chunk, grid, pool))
    if path is None:
        n = 0
        for rec in chunks:
            n += len(rec)
            pool.give(rec)
    else:
        n = write_stl(path, chunks, pool=pool)
    dt = time.perf_counter() - t0
    kind = ("batched" if batched else "per-hub") + ("" if path else ", no file")
    return {"path": kind, "workers": workers, "seconds": round(dt, 3),
            "triangles": n, "triangles_per_s": round(n / dt), "hub_templates": len(tess.templates)}


def _writer_only(lat: Lattice, style: str, levels: int, path: str) -> dict:
    """The STL writer alone (one thread): snap, encode and write each box as it comes, the
    tessellation between boxes not timed. Boxes one at a time, as in the stream (holding them
    all first would time the page faults of a whole mesh in memory, not the writer)."""
    grid, pool, dt, n = output_grid(lat), RecordPool(), 0.0, 0
    with open(path, "wb") as fh:
        w = StlWriter(fh, stl_header())
        for chunk in iter_triangles(lat, None, style, levels):
            t0 = time.perf_counter()
            rec = stl_chunk(chunk, grid, pool)
            w.write_records(rec)
            pool.give(rec)
            n += len(rec)
            dt += time.perf_counter() - t0
        t0 = time.perf_counter()
        w.close()
        fh.flush()
        dt += time.perf_counter() - t0
    size = os.path.getsize(path)
    os.remove(path)
    return {"seconds": round(dt, 3), "triangles": n, "triangles_per_s": round(n / dt),
            "bytes": size, "bytes_alone_s": round(_bytes_alone(size, path), 3)}


def _bytes_alone(size: int, path: str) -> float:
    """Seconds to write ``size`` bytes already in memory to ``path`` in 64 MiB blocks, the way
    the STL writer writes (past the page cache where the file system allows it,
    ``ple.io.files.DirectWriter``; else plainly, no sync): the floor under any STL writer of
    that file here."""
    block = np.random.default_rng(0).integers(0, 256, 64 << 20, dtype=np.uint8).tobytes()
    t0 = time.perf_counter()
    with open(path, "wb") as fh:
        direct = direct_writer(fh)  # as StlWriter chooses
        for lo in range(0, size, len(block)):
            (direct or fh).write(block[:min(len(block), size - lo)])
        if direct is not None:
            direct.close()
    dt = time.perf_counter() - t0
    os.remove(path)
    return dt


def _whole(lat: Lattice, style: str, levels: int, workers: int, path: str) -> dict:
    """What ``ple mesh --out x.stl --workers W`` does, end to end: the cleanliness check (its hub
    templates reused by the stream), then the checked stream or the exact unions, the file."""
    info: dict = {}
    t0 = time.perf_counter()
    n = write_mesh(MeshRequest(lat, style=style, levels=levels or None, workers=workers), path, info=info)
    dt = time.perf_counter() - t0
    rep = info.get("unclean")
    return {"path": "ple mesh", "workers": workers, "seconds": round(dt, 3), "triangles": n,
            "triangles_per_s": round(n / dt), "unclean_hubs": None if rep is None else int(len(rep.nodes))}


def _check(lat: Lattice, style: str, levels: int) -> dict:
    t0 = time.perf_counter()
    report, _ = Tessellator(lat, lat.region(), style, levels, 16).find_unclean()
    return {"check_s": round(time.perf_counter() - t0, 3), "unclean_hubs": int(len(report.nodes))}


def child_row(lattice: str, n: int, style: str, levels: int, kind: str, workers: int) -> dict:
    """One measurement in this (child) process: ``kind`` is batched, per-hub, writer, check, whole
    (``ple mesh`` end to end) or no-file (batched, the records counted instead of written)."""
    lat = bench_lattice(lattice, n)
    with tempfile.TemporaryDirectory(prefix="ple-bench-curved-") as d:
        path = os.path.join(d, "out.stl")
        if kind == "writer":
            row = _writer_only(lat, style, levels, path)
        elif kind == "check":
            row = _check(lat, style, levels)
        elif kind == "whole":
            row = _whole(lat, style, levels, workers, path)
        elif kind == "no-file":
            row = _stream(lat, style, levels, True, workers, None)
        else:
            row = _stream(lat, style, levels, kind == "batched", workers, path)
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    row["peak_rss_gb"] = round(me.ru_maxrss / 1e6, 3)  # VmHWM, KB on Linux
    row["cpu_user_s"] = round(me.ru_utime + kids.ru_utime, 2)  # template processes included
    row["cpu_sys_s"] = round(me.ru_stime + kids.ru_stime, 2)  # page faults, the file's page cache
    return row


def _child(*spec) -> dict:
    env = dict(os.environ)
    core = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env["PYTHONPATH"] = core + os.pathsep + env.get("PYTHONPATH", "")
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(spec)], capture_output=True, text=True, env=env)
    if out.returncode != 0:
        raise PleError(f"bench row {spec} failed: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _fastest(spec: tuple, repeat: int) -> dict:
    """The fastest of ``repeat`` runs of one child row (this 2-core VM's page faults and file
    writes vary by seconds from run to run), with every run's seconds."""
    runs = [_child(*spec) for _ in range(max(1, repeat))]
    best = min(runs, key=lambda r: r["seconds"])
    best["seconds_all"] = [r["seconds"] for r in runs]
    return best


def rows(n: int, warped_n: int, styles: list[str], levels: int, per_hub: bool = True, repeat: int = 3) -> list[dict]:
    """The table of issue 14: per lattice and style, the batched path on 1 and 2 workers (each
    the fastest of ``repeat`` runs), the per-hub path (curved only: the baseline, one run), the
    writer alone, and the cleanliness check."""
    plan = [("curved", n, s) for s in styles] + [("regular", n, s) for s in styles]
    if warped_n:
        plan.append(("warped", warped_n, "cnt"))  # refined 10⁶ beams is ~20 GB of STL
    out = []
    for name, size, style in plan:
        lv = levels if style == "refined" else 0
        runs = [_child(name, size, style, lv, "per-hub", 1)] if per_hub and name == "curved" else []
        runs += [_fastest((name, size, style, lv, "batched", w), repeat) for w in (1, 2)]
        runs.append(_fastest((name, size, style, lv, "no-file", 2), repeat))
        row = {"lattice": name, "n": size, "groups": size**3, "style": style, "levels": lv, "runs": runs,
               "stl_writer_only": _child(name, size, style, lv, "writer", 1),
               "cleanliness_check": _child(name, size, style, lv, "check", 1),
               "ple_mesh": _child(name, size, style, lv, "whole", 2)}
        best = min(r["seconds"] for r in runs if r["path"] == "batched")
        row["best_triangles_per_s"] = round(runs[-1]["triangles"] / best)
        if runs[0]["path"] == "per-hub":
            row["speedup_vs_per_hub"] = round(runs[0]["seconds"] / best, 2)
        out.append(row)
    return out


def run(args) -> dict:
    if not 2 <= args.n <= 200:
        raise PleError(f"--n {args.n}: expected 2..200")
    if args.warped_n and not 2 <= args.warped_n <= 200:
        raise PleError(f"--warped-n {args.warped_n}: expected 0 or 2..200")
    if not 1 <= args.repeat <= 20:
        raise PleError(f"--repeat {args.repeat}: expected 1..20")
    if not 0 <= args.levels <= 4:
        raise PleError(f"--levels {args.levels}: expected 0..4")
    styles = [s.strip() for s in args.styles.split(",") if s.strip()]
    bad = [s for s in styles if s not in ("cnt", "chocc", "refined")]
    if bad or not styles:
        raise PleError(f"--styles {echo(args.styles)}: expected some of cnt, chocc, refined")
    return {"benchmark": "curved", "n": args.n, "machine": f"{os.cpu_count()} cores",
            "load_average_at_start": list(os.getloadavg()),
            "repeat": args.repeat,
            "rows": rows(args.n, args.warped_n, styles, args.levels, not args.no_per_hub, args.repeat)}
