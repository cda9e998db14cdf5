"""``ple info LATTICE [--json]``: counts, similarity kinds, bounds, beams, area, volume."""

from __future__ import annotations

import json

from ..measure.integrals import lattice_measures
from ..model.lattice import Lattice
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("info", help="counts, similarity kinds, bounds, beam count, area, volume")
    add_lattice_args(p)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def lattice_info(lat: Lattice) -> dict:
    lo, hi = lat.bounds()
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
        "bounds": {"min": lo.tolist(), "max": hi.tolist()},
        "mean_radius": lat.mean_radius(),
    }
    if lat.group_map is not None:  # groups placed by a map, not by U, V, W similarities
        info["group_map"] = lat.group_map.describe()
        del info["similarities"], info["placement"]
    info.update(lattice_measures(lat))
    return info


def run(args) -> int:
    info = lattice_info(lattice_from_args(args))
    if args.json:
        print(json.dumps(info, indent=1))
        return 0
    print(f"groups      {info['counts'][0]} x {info['counts'][1]} x {info['counts'][2]} = {info['groups']:,}")
    print(f"nodes       {info['nodes']:,} ({info['template_nodes']} per group)")
    print(f"beams       {info['beams']:,} ({info['beam_patterns']} beam-patterns)")
    if "group_map" in info:
        print(f"groups by   {info['group_map']['kind']} map ({info['group_map']['note']})")
    for name, s in info.get("similarities", {}).items():
        cum = " (given cumulatively)" if s["cumulative"] else ""
        print(f"{name}           {s['kind']}{cum}")
    print(f"bounds      {_fmt(info['bounds']['min'])} .. {_fmt(info['bounds']['max'])}")
    print(f"mean radius {info['mean_radius']:.6g}")
    for key in ("area", "volume"):
        if key in info:
            print(f"{key:<11} {info[key]:.9g}")
    return 0


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
