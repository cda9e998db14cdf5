"""``ple info LATTICE [--json]``: counts, similarity kinds, bounds, beams, area, volume."""

from __future__ import annotations

import json
import math

from ..budget import fast_bounds
from ..errors import PleError
from ..lattice import Lattice
from ..measure import lattice_measures
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("info", help="counts, similarity kinds, bounds, beam count, area, volume")
    add_lattice_args(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def lattice_info(lat: Lattice) -> dict:
    lo, hi, exact = fast_bounds(lat)  # closed form or bounded scan: seconds even for 10^12 groups
    info = {
        "counts": list(lat.counts),
        "groups": lat.groups,
        "template_nodes": len(lat.nodes),
        "beam_patterns": len(lat.beams),
        "nodes": lat.node_count(),
        "beams": lat.beam_count(),
        "similarities": {name: {"kind": d.incremental.kind, "cumulative": d.cumulative,
                                "incremental": d.incremental.to_dict()}
                         for name, d in (("U", lat.u), ("V", lat.v), ("W", lat.w))},
        "placement": lat.placement.to_dict(),
        "bounds": {"min": lo.tolist(), "max": hi.tolist(), "exact": exact},
        "mean_radius": lat.mean_radius(),
    }
    info.update(lattice_measures(lat))
    for key in ("area", "volume", "mean_radius"):
        if key in info and not math.isfinite(info[key]):
            raise PleError(f"the lattice's {key} overflows ({info[key]}); its sizes are too large or too small")
    return info


def run(args) -> int:
    info = lattice_info(lattice_from_args(args))
    if args.json:
        print(json.dumps(info, indent=1))
        return 0
    print(f"groups      {info['counts'][0]} x {info['counts'][1]} x {info['counts'][2]} = {info['groups']:,}")
    print(f"nodes       {info['nodes']:,} ({info['template_nodes']} per group)")
    print(f"beams       {info['beams']:,} ({info['beam_patterns']} beam-patterns)")
    for name, s in info["similarities"].items():
        cum = " (given cumulatively)" if s["cumulative"] else ""
        print(f"{name}           {s['kind']}{cum}")
    approx = "" if info["bounds"]["exact"] else "  (approximate: sampled groups)"
    print(f"bounds      {_fmt(info['bounds']['min'])} .. {_fmt(info['bounds']['max'])}{approx}")
    print(f"mean radius {info['mean_radius']:.6g}")
    for key in ("area", "volume"):
        if key in info:
            print(f"{key:<11} {info[key]:.9g}")
    return 0


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
