"""Area and volume of presets: time per preset and hubs measured, vs the old per-hub quadrature.

New path: ``lattice_measures`` (closed-form series, congruent hubs once, exact one-beam hubs
plus a batched adaptive overlap quadrature). Baseline, in the same run: the per-hub
quadrature ``hub_measures`` (the previous path) on ``--baseline-hubs`` of the distinct hub
geometries, extrapolated to all distinct hubs the new path measures (the old path measured
every (geometry, beam subset) separately). Also the largest deviation of those hubs from the
baseline's own values."""

from __future__ import annotations

import time

import numpy as np

from ..measure import integrals as measure
from ..program.sources import load_lattice

PRESETS = "thesis_regular,thesis_cylindrical,thesis_warped,fig6_3,octet,fcc,cubic,bcc,warped"


def add_arguments(p) -> None:
    p.add_argument("--presets", default=PRESETS, help=f"comma-separated presets (default {PRESETS})")
    p.add_argument("--baseline-hubs", type=int, default=2, help="hubs timed on the old path per preset (default 2)")


def run(args) -> dict:
    out = {"machine": "2 shared cores", "presets": {}}
    for name in args.presets.split(","):
        lat = load_lattice(name, {})
        t0, c0 = time.perf_counter(), time.process_time()
        m = measure.lattice_measures(lat)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        row = {"groups": lat.groups, "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
               **{k: m.get(k) for k in ("area", "volume", "area_method", "hubs", "hub_shapes", "hub_geometries")}}
        if "area" in m:
            row.update(_baseline(lat, m, args.baseline_hubs))
        out["presets"][name] = row
    return out


def _baseline(lat, m: dict, count: int) -> dict:
    """Time the old per-hub path on ``count`` hubs and compare them with the new batch."""
    reach = [max([abs(b.offset[d]) for b in lat.beams], default=0) for d in range(3)]
    segs = [measure.row_segments(c, r, s) for c, r, s in zip(lat.counts, reach, measure.similar_axes(lat))]
    idx, _, _ = measure.rep_hubs(lat, segs)
    rng = np.random.default_rng(0)
    pick = rng.choice(len(idx), min(count, len(idx)), replace=False)
    ra, off, rb, present, _ = measure.hub_geometry(lat, idx[pick])
    t0 = time.perf_counter()
    old = [measure.hub_measures(float(ra[h]), [measure.HalfBeam(off[h, b], float(ra[h]), float(rb[h, b]))
                                               for b in np.nonzero(present[h])[0]]) for h in range(len(pick))]
    per_hub = (time.perf_counter() - t0) / len(pick)
    new_a, new_v = measure.hub_measures_batch(ra, off, rb, present)
    dev = max(max(abs(a / o[0] - 1), abs(v / o[1] - 1)) for a, v, o in zip(new_a, new_v, old))
    return {"baseline_s_per_hub": round(per_hub, 3), "baseline_extrapolated_s": round(per_hub * m["hub_shapes"], 1),
            "baseline_hubs_timed": len(pick), "max_rel_dev_vs_baseline": float(f"{dev:.2g}")}
