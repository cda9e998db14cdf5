"""LiL benchmark: the thesis examples (Fig. 7.9, Table 7.1) with a KD-tree and a naive baseline.

Cases (fine: 2 balls, 14 beam-patterns; coarse: 1 ball, 3 beam-patterns):
regular 75³ vs regular 9³, cylindrical 32×128×128 vs 5×17×9, regular 64³ vs semi-regular 8³.
``--thesis-sample`` runs thesis §7.4's own method beside ours: two BIQs per valid fine beam
(one per end ball) against the coarse lattice, every RangeFinder path (the thesis' O(1), O(ū),
O(ūv̄), and the pulled-back query, ``ple.queries.pullback``, which answers the same general case
as O(ūv̄)) and the naive one, on a process pool (``--workers``), timed on a random sample of fine
beams and extrapolated to all of them (``--thesis-full`` paths on every beam); per BIQ it is set
beside Table 7.1's time × 8 threads / (2 × beams).
``--big`` also streams a LiL over a fine lattice of at least 10⁸ beams in a subprocess and
reports its peak memory (the child's VmHWM; its ru_maxrss is reported too).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from scipy.spatial import cKDTree

from ..algebra.elements import ball_ball_interfere, ball_beam_interfere, enclosing_ball
from ..filters.base import FilteredLattice
from ..filters.implicit import FourierField, ImplicitFilter, TPMSField, sample_grid
from ..filters.lil import lil
from ..program.sources import load_lattice
from ..queries import pullback
from ..queries.biq import query
from ..queries.rangefinder import PATH_ORDER, cached_plan, lattice_hits
from ._timing import best_of

CASES = [
    # name, fine preset, fine params, coarse preset, the seed's best time (s, 8 threads) and its source:
    # thesis Table 7.1 (i7-7700K, Fig. 7.9: 75³ fine lattices) or RangeFinder paper Table 1
    # (i7-6820HQ, Fig. 12: the semi-regular case on a 64³ fine lattice, 5.87 min)
    ("regular", "thesis_regular", {}, "lil_regular_coarse", 3.44, "thesis Table 7.1"),
    ("cylindrical", "thesis_cylindrical", {}, "lil_cylindrical_coarse", 22.3, "thesis Table 7.1"),
    ("semiregular", "thesis_regular", {"n": 64}, "lil_semiregular_coarse", 352.0, "RangeFinder paper Table 1"),
]

# thesis Table 7.1 (s, 8 threads, i7-7700K, Java) and RangeFinder paper Table 1 (min, 8 threads,
# i7-6820HQ): two BIQs per fine beam (thesis §7.4, paper §7), the LiLs of thesis Fig. 7.9 / paper Fig. 12
TABLE_7_1 = [
    # case, fine preset, fine params, coarse preset, coarse params, thesis {path: s}, paper {path: min}
    ("regular 75³ / 9³", "thesis_regular", {}, "lil_regular_coarse", {},
     {"naive": 427.0, "uv": 95.5, "u": 13.7, "1": 3.44}, {"naive": 10.3, "uv": 2.20, "u": 0.31, "1": 0.067}),
    ("cylindrical 32×128×128 / 5×17×9", "thesis_cylindrical", {}, "lil_cylindrical_coarse", {},
     {"naive": 1480.0, "uv": 239.0, "u": 22.3}, {"naive": 37.2, "uv": 5.98, "u": 0.541}),
    ("semi-regular 75³ / 8³", "thesis_regular", {}, "lil_semiregular_coarse", {"span": 74.0},
     {"naive": 869.0, "uv": 266.0}, {}),
    ("semi-regular 64³ / 8³", "thesis_regular", {"n": 64}, "lil_semiregular_coarse", {},
     {}, {"naive": 19.10, "uv": 5.87}),
]
THESIS_THREADS = 8

BIG_SCRIPT = """
import json, resource, sys, time
from ple.filters import lil
from ple import load_lattice
from ple.io.chunks import stream_filter
n, out = int(sys.argv[1]), sys.argv[2]
fine = load_lattice("thesis_regular", {"n": n})
coarse = load_lattice("lil_regular_coarse", {"span": n - 1.0})
t0 = time.perf_counter()
m = stream_filter(lil(fine, coarse), out, progress=False)
# VmHWM is this process image's own peak RSS; ru_maxrss would also count the parent's RSS at
# fork time (Linux keeps it across exec), which is not ours
hwm = [line.split()[1] for line in open("/proc/self/status") if line.startswith("VmHWM")]
print(json.dumps({"seconds": time.perf_counter() - t0, "nodes_kept": m["nodes"], "beams_kept": m["beams"],
                  "chunks": len(m["chunks"]), "fine_nodes": fine.node_count(), "fine_beams": fine.beam_count(),
                  "peak_rss_mb": int(hwm[0]) / 1024 if hwm else None,
                  "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def add_arguments(p) -> None:
    p.add_argument("--repeat", type=int, default=3, help="best of this many runs (default 3)")
    p.add_argument("--big", action="store_true", help="also stream a LiL over a >= 1e8-beam fine lattice")
    p.add_argument("--biq", action="store_true", help="also time LiL through ple.biq.any_hit (slow)")
    p.add_argument("--thesis-sample", type=int, default=20000,
                   help="fine beams timed by the thesis' method, two BIQs each (default 20000; 0 skips)")
    p.add_argument("--thesis-naive-sample", type=int, default=200, help="fine beams timed on the naive path")
    p.add_argument("--thesis-full", default="1",
                   help="paths run on every fine beam, not a sample (comma list of 1,u,uv,pullback; default 1; "
                        "'' none)")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help="processes (default 2)")
    p.add_argument("--seed", type=int, default=2024)


def kdtree_mask(fine_centers, fine_radii, coarse_ev):
    """Baseline: KD-tree over fine centres, one ball query per coarse element's enclosing ball."""
    tree = cKDTree(fine_centers)
    rmax = fine_radii.max()
    keep = np.zeros(len(fine_centers), dtype=bool)
    for c, r in zip(coarse_ev.center, coarse_ev.radius):
        cand = np.asarray(tree.query_ball_point(c, r + rmax), dtype=np.int64)
        keep[cand[ball_ball_interfere(fine_centers[cand], fine_radii[cand], c, r)]] = True
    for a, b in coarse_ev.beam_nodes:
        ca, ra, cb, rb = coarse_ev.center[a], coarse_ev.radius[a], coarse_ev.center[b], coarse_ev.radius[b]
        ec, er = enclosing_ball(ca, ra, cb, rb)
        cand = np.asarray(tree.query_ball_point(ec, float(er) + rmax), dtype=np.int64)
        keep[cand[ball_beam_interfere(fine_centers[cand], fine_radii[cand], ca, ra, cb, rb)]] = True
    return keep


def naive_mask(fine_centers, fine_radii, coarse_ev):
    """Baseline: every fine ball against every coarse element, vectorized in numpy over all fine
    balls, one coarse element at a time (faster than blocks of both: no large temporaries)."""
    keep = np.zeros(len(fine_centers), dtype=bool)
    for c, r in zip(coarse_ev.center, coarse_ev.radius):
        keep |= ball_ball_interfere(fine_centers, fine_radii, c, r)
    for a, b in coarse_ev.beam_nodes:
        keep |= ball_beam_interfere(fine_centers, fine_radii, coarse_ev.center[a], coarse_ev.radius[a],
                                    coarse_ev.center[b], coarse_ev.radius[b])
    return keep


def run_case(name, fine_name, fine_params, coarse_name, thesis_s, source, repeat, with_biq) -> dict:
    fine = load_lattice(fine_name, fine_params)
    coarse = load_lattice(coarse_name)
    result = {}
    seconds = best_of(lambda: result.__setitem__("ev", lil(fine, coarse).evaluate()), repeat)
    ev = result["ev"]
    row = {"case": name, "fine": f"{fine_name} {'x'.join(map(str, fine.counts))}",
           "coarse": f"{coarse_name} {'x'.join(map(str, coarse.counts))}", "seconds": seconds,
           "seed_seconds_8_threads": thesis_s, "seed_source": source, "speedup_vs_seed": thesis_s / seconds,
           "nodes_kept": len(ev.node_index), "fine_nodes": fine.node_count(),
           "beams_kept": len(ev.beam_index), "fine_beams": fine.beam_count()}
    # baseline in the same run: KD-tree over the fine centres, whole lattice, same coarse elements
    full_c, full_r = fine.region_balls()
    full_c, full_r = full_c.reshape(-1, 3), full_r.reshape(-1)
    t0 = time.perf_counter()
    keep = kdtree_mask(full_c, full_r, coarse.evaluate())
    row["kdtree_baseline_seconds"] = time.perf_counter() - t0
    row["kdtree_agrees"] = int(keep.sum()) == len(ev.node_index)
    row["speedup_vs_kdtree"] = row["kdtree_baseline_seconds"] / seconds
    if with_biq:
        t0 = time.perf_counter()
        evb = lil(fine, coarse, method="biq").evaluate()
        row["biq_method_seconds"] = time.perf_counter() - t0
        row["biq_agrees"] = len(evb.node_index) == len(ev.node_index) and len(evb.beam_index) == len(ev.beam_index)
    return row


def naive_row(repeat) -> dict:
    """Naive all-pairs baseline on a 25³ corner of the regular case, against ours on the same."""
    fine = load_lattice("thesis_regular", {"n": 25})
    coarse = load_lattice("lil_regular_coarse")
    cev = coarse.evaluate()
    c, r = fine.region_balls()
    c, r = c.reshape(-1, 3), r.reshape(-1)
    t_naive = best_of(lambda: naive_mask(c, r, cev), 1)
    ours = {}
    t_ours = best_of(lambda: ours.__setitem__("ev", lil(fine, coarse).evaluate()), repeat)
    keep = naive_mask(c, r, cev)
    same = fine.evaluate().select(keep)
    return {"case": "naive baseline, regular 25^3 vs 9^3", "naive_seconds": t_naive, "seconds": t_ours,
            "speedup_vs_naive": t_naive / t_ours,
            "agrees": bool(np.array_equal(same.beam_index, ours["ev"].beam_index))}


def implicit_rows(repeat) -> list[dict]:
    """Implicit-field filters over the regular 75³ fine lattice: a TPMS sheet, and a T_d-symmetric
    Fourier fit of a sphere's signed distance (004_), against a direct complex-exponential sum."""
    fine = load_lattice("thesis_regular")
    gyroid = ImplicitFilter(TPMSField("gyroid", 12.0), 0.3, "sheet")
    out = {}
    t_gyroid = best_of(lambda: out.__setitem__("ev", FilteredLattice(fine, gyroid).evaluate()), repeat)
    rows = [{"case": "gyroid sheet filter, regular 75^3", "seconds": t_gyroid,
             "nodes_kept": len(out["ev"].node_index), "beams_kept": len(out["ev"].beam_index)}]
    t0 = time.perf_counter()
    sdf = sample_grid(lambda p: np.linalg.norm(p - [0.12, 0.05, 0.0], axis=1) - 0.3, 32)
    field = FourierField.fit(sdf, max_terms=400, cell=15.0)
    t_fit = time.perf_counter() - t0
    pts = fine.region_balls()[0].reshape(-1, 3)
    t_eval = best_of(lambda: field(pts), repeat)
    x = field.local(pts[:100_000])
    t_direct = best_of(lambda: np.real(np.exp(2j * np.pi * (x @ field.freqs.T)) @ field.coeffs), 1)
    rows.append({"case": "Fourier T_d fit (N=32, sphere SDF) and evaluation at 843,750 node centres",
                 "fit_seconds": t_fit, "terms": len(field.freqs), "eval_seconds": t_eval,
                 "points_per_second": len(pts) / t_eval,
                 "direct_complex_sum_seconds_estimated": t_direct * len(pts) / 100_000,
                 "speedup_vs_direct": t_direct * len(pts) / 100_000 / t_eval})
    gyroid_fit = FourierField.fit(sample_grid(lambda p: TPMSField("gyroid")(p), 8), symmetric=False, cell=12.0)
    t_small = best_of(lambda: gyroid_fit(pts), repeat)
    rows.append({"case": "Fourier fit of a gyroid (12 terms) evaluated at 843,750 node centres",
                 "eval_seconds": t_small, "points_per_second": len(pts) / t_small,
                 "tpms_formula_seconds": best_of(lambda: TPMSField("gyroid", 12.0)(pts), repeat)})
    return rows


def big_row() -> dict:
    """A streamed LiL over >= 1e8 fine beams in a child process; peak RSS of the child."""
    n = 2
    while load_lattice("thesis_regular", {"n": n}).beam_count() < 10**8:
        n += 1
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", BIG_SCRIPT, str(n), f"{tmp}/chunks"], capture_output=True,
                              text=True, check=True)
        wall = time.perf_counter() - t0
    row = json.loads(proc.stdout)
    row["case"] = f"big: thesis_regular {n}^3 vs lil_regular_coarse 9^3, streamed"
    row["wall_seconds_with_startup"] = wall
    return row


def fine_beam_ends(fine, sample: int, rng) -> tuple[np.ndarray, int]:
    """(2m, 4) node indices (i, j, k, n): both end nodes of m random valid fine beams (a beam is
    valid when its far group lies inside the lattice, as the thesis' "each valid beam"), and the
    number of valid beams."""
    counts = np.array(fine.counts)
    off = np.array([b.offset for b in fine.beams], np.int64)
    ends = np.array([(b.n1, b.n2) for b in fine.beams], np.int64)
    valid = np.prod(counts[None, :] - np.abs(off), axis=1)  # groups whose beam stays inside, per pattern
    total = int(valid.sum())
    pick = rng.choice(total, min(sample, total), replace=False)
    pat = np.searchsorted(np.cumsum(valid), pick, side="right")
    local = pick - (np.cumsum(valid) - valid)[pat]
    span = counts[None, :] - np.abs(off[pat])
    ijk = _unravel(local, span)
    lo = np.maximum(0, -off[pat])  # a beam with a negative offset starts one group in
    a = ijk + lo
    b = a + off[pat]
    idx = np.concatenate([np.column_stack([a, ends[pat, 0]]), np.column_stack([b, ends[pat, 1]])])
    return idx, total


def _unravel(flat: np.ndarray, span: np.ndarray) -> np.ndarray:
    """Row-wise unravel of ``flat`` (m,) in per-row shapes ``span`` (m, 3)."""
    k = flat % span[:, 2]
    j = (flat // span[:, 2]) % span[:, 1]
    i = flat // (span[:, 2] * span[:, 1])
    return np.stack([i, j, k], axis=1)


def _biq_chunk(job) -> tuple[float, float, int]:
    """Worker: (wall seconds, CPU seconds, queries with a hit) of one path on one chunk of end
    balls (plan built first). CPU seconds are this process's own: on a shared machine they are
    what one thread of its own would take, wall seconds include waiting for a core."""
    coarse_name, cparams, c, r, path = job
    coarse = load_lattice(coarse_name, cparams)
    if path in ("naive", "pullback"):  # every coarse element per query, or the pulled-back query
        run = (lambda c, r: query(coarse, c, r, method="naive")) if path == "naive" else (
            lambda c, r: pullback.query(coarse, c, r))
        run(c[:1], r[:1])
        t0, p0 = time.perf_counter(), time.process_time()
        found = run(c, r)
        sec, cpu = time.perf_counter() - t0, time.process_time() - p0
        return sec, cpu, sum(bool(len(q.nodes) or len(q.beams)) for q in found)
    lattice_hits(coarse, c[:1], r[:1], path=path)
    t0, p0 = time.perf_counter(), time.process_time()
    nh, bh, _ = lattice_hits(coarse, c, r, path=path)
    sec, cpu = time.perf_counter() - t0, time.process_time() - p0
    hit = np.zeros(len(c), bool)
    for h in (nh, bh):
        hit[np.asarray(h, np.int64)[:, 0]] = True
    return sec, cpu, int(hit.sum())


def thesis_method_rows(sample: int, naive_sample: int, workers: int, seed: int, full=("1",)) -> list[dict]:
    """Table 7.1 by the thesis' method: two BIQs per valid fine beam against the coarse lattice,
    every path, ``workers`` processes; the paths in ``full`` on every beam, the others timed on
    ``sample`` beams and extrapolated to all beams."""
    rng = np.random.default_rng(seed)
    rows = []
    with ProcessPoolExecutor(workers) as pool:
        for case, fine_name, fparams, coarse_name, cparams, theirs, paper in TABLE_7_1:
            fine, coarse = load_lattice(fine_name, fparams), load_lattice(coarse_name, cparams)
            idx, beams = fine_beam_ends(fine, sample, rng)
            c, r = fine.node_balls(idx)
            biqs = 2 * beams
            ours = {}
            best = cached_plan(coarse).path
            general = ["pullback"] if pullback.fits(coarse) else []
            for path in list(PATH_ORDER[PATH_ORDER.index(best):]) + general + ["naive"]:
                if path == "naive":  # the same beams' first ones, both ends
                    m = min(naive_sample, len(idx) // 2)
                    pc = np.concatenate([c[:m], c[len(idx) // 2:len(idx) // 2 + m]])
                    pr = np.concatenate([r[:m], r[len(idx) // 2:len(idx) // 2 + m]])
                elif path in full:
                    pc, pr = fine.node_balls(fine_beam_ends(fine, beams, rng)[0])
                else:
                    pc, pr = c, r
                parts = np.array_split(np.arange(len(pc)), workers)
                t0 = time.perf_counter()
                done = list(pool.map(_biq_chunk, [(coarse_name, cparams, pc[p], pr[p], path) for p in parts]))
                wall = time.perf_counter() - t0
                busy = sum(d[0] for d in done)  # wall seconds inside the BIQs, summed over the processes
                cpu = sum(d[1] for d in done)
                ours[path] = {"timed_biqs": len(pc), "all_biqs_run": len(pc) == biqs,
                              "us_per_biq": busy / len(pc) * 1e6, "cpu_us_per_biq": cpu / len(pc) * 1e6,
                              "extrapolated_seconds_on_workers": busy / len(pc) * biqs / workers,
                              "extrapolated_cpu_seconds_on_workers": cpu / len(pc) * biqs / workers,
                              "pool_wall_seconds": wall, "queries_with_a_hit": sum(d[2] for d in done)}
            rows.append({
                "case": case, "fine": f"{fine_name} {'x'.join(map(str, fine.counts))}",
                "coarse": f"{coarse_name} {'x'.join(map(str, coarse.counts))}", "fine_beams": beams,
                "biqs": biqs, "workers": workers, "ours": ours,
                "thesis_seconds_8_threads": theirs,
                "thesis_us_per_biq_per_thread": {k: v * THESIS_THREADS / biqs * 1e6 for k, v in theirs.items()},
                "rangefinder_table_1_seconds_8_threads": {k: 60.0 * v for k, v in paper.items()},
                "rangefinder_us_per_biq_per_thread": {k: 60.0 * v * THESIS_THREADS / biqs * 1e6
                                                      for k, v in paper.items()},
                "note": "ours: every fine beam where all_biqs_run, else a random sample of fine beams (both "
                        "end balls each) extrapolated to all; per BIQ the wall and the CPU time inside the BIQs "
                        "summed over the processes (CPU: what an unshared core would take). "
                        "thesis / paper: Table 7.1 / Table 1 total on 8 threads, per BIQ = total x 8 / BIQs."})
    return rows


def run(args) -> dict:
    rows = [big_row()] if args.big else []  # first, while this process is still small
    if args.thesis_sample:
        full = tuple(p for p in args.thesis_full.split(",") if p)
        rows += thesis_method_rows(args.thesis_sample, args.thesis_naive_sample, args.workers, args.seed, full)
    rows += [run_case(*case, args.repeat, args.biq) for case in CASES]
    rows.append(naive_row(args.repeat))
    rows += implicit_rows(args.repeat)
    return {"benchmark": "lil", "machine": "2 shared cores", "rows": rows}
