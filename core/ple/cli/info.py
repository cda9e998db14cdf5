"""``ple info LATTICE [--region R] [--json]``: counts, similarity kinds, bounds, beams, area,
volume — of what the lattice keeps (its filter applied), in the whole index box or a region."""

from __future__ import annotations

import math

import numpy as np

from ..errors import PleError
from ..io.files import strict_json
from ..measure.check import is_clean
from ..measure.integrals import MAX_KEPT_NODES, kept_measures, lattice_measures
from ..measure.moments import mass_properties
from ..model.budget import fast_bounds
from ..model.lattice import Lattice
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("info", help="counts, similarity kinds, bounds, beam count, area, volume")
    add_lattice_args(p)
    p.add_argument("--region", help="I0:I1,J0:J1,K0:K1 (half-open): report this index box only")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=run)


def lattice_info(lat: Lattice, region=None) -> dict:
    """Everything ``ple info`` reports. Without a filter, counts are closed forms and the whole
    lattice's area and volume come from the geometric series; with a filter (or a region), the
    kept nodes are decided slab by slab and the kept hubs measured (up to MAX_KEPT_NODES)."""
    r = lat.region(region)
    whole = str(r) == str(lat.region())
    info = {
        "counts": list(lat.counts),
        "region": str(r),
        "groups": r.groups,
        "template_nodes": len(lat.nodes),
        "beam_patterns": len(lat.beams),
        "filtered": lat.filter is not None,
        "similarities": {name: {"kind": d.incremental.kind, "cumulative": d.cumulative,
                                "incremental": d.incremental.to_dict()}
                         for name, d in (("U", lat.u), ("V", lat.v), ("W", lat.w))},
        "placement": lat.placement.to_dict(),
        "mean_radius": lat.mean_radius(),
    }
    if lat.group_map is not None:  # groups placed by a map, not by U, V, W similarities
        info["group_map"] = lat.group_map.describe()
        del info["similarities"], info["placement"]
    if lat.filter is None:
        if lat.group_map is None:
            lo, hi, exact = fast_bounds(lat, r)  # closed form or bounded scan: seconds even for 10^12 groups
        else:
            (lo, hi), exact = lat.bounds(r), True
        info.update(nodes=lat.node_count(r), beams=lat.beam_count(r),
                    bounds={"min": lo.tolist(), "max": hi.tolist(), "exact": exact})
        return _measures(lat, r, whole, info)
    info.update(program_nodes=lat.node_count(r), program_beams=lat.beam_count(r))
    if lat.node_count(r) > MAX_KEPT_NODES:
        info["counts_method"] = (f"skipped: {lat.node_count(r):,} nodes to decide one by one (limit "
                                 f"{MAX_KEPT_NODES:,}; give a smaller --region)")
        return info
    nodes = beams = 0
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for _, ev in lat.iter_evaluation(r):
        nodes, beams = nodes + len(ev.node_index), beams + len(ev.beam_index)
        if len(ev.radius):
            lo = np.minimum(lo, (ev.center - ev.radius[:, None]).min(axis=0))
            hi = np.maximum(hi, (ev.center + ev.radius[:, None]).max(axis=0))
    info.update(nodes=nodes, beams=beams)
    if nodes:
        info["bounds"] = {"min": lo.tolist(), "max": hi.tolist(), "exact": True}
    return _measures(lat, r, whole, info)


def _measures(lat: Lattice, r, whole: bool, info: dict) -> dict:
    """Area, volume, centroid and inertia (about the centroid, unit density) of what is kept, in one
    computation (``mass_properties``; lattices whose groups a map places: area and volume per hub);
    ``clean``: True/False, or None when checking would cost more than a quick look (``ple check``
    gives the full report)."""
    if lat.group_map is not None:  # no similar hubs to move moments with: ple check and moments skip it
        info.update(lattice_measures(lat) if whole else kept_measures(lat, r))
        _check_finite_measures(info)
        info["clean"] = None
        return info
    props = mass_properties(lat, r)
    info["area_method"] = props["method"]
    if "volume" in props:
        info.update(area=props["area"], volume=props["volume"], hubs=props["hubs"], hub_shapes=props["hub_shapes"],
                    quadrature_error=props["quadrature_error"])
        _check_finite_measures(info)
        if props["centroid"] is not None:
            info.update(centroid=np.asarray(props["centroid"]).tolist(), inertia=np.asarray(props["inertia"]).tolist())
    info["clean"] = is_clean(lat, r)
    return info


def _check_finite_measures(info: dict) -> None:
    for key in ("area", "volume", "mean_radius"):
        if key in info and not math.isfinite(info[key]):
            raise PleError(f"the lattice's {key} overflows ({info[key]}); its sizes are too large or too small")


def run(args) -> int:
    lat = lattice_from_args(args)
    info = lattice_info(lat, args.region)
    if args.json:
        print(strict_json(info, "the lattice info", indent=1))
        return 0
    c = info["counts"]
    print(f"groups      {c[0]} x {c[1]} x {c[2]} = {lat.groups:,}"
          + (f" (region {info['region']}: {info['groups']:,})" if args.region else ""))
    if info["filtered"]:
        print(f"filter      {type(lat.filter).__name__} (counts, bounds, area and volume are of what it keeps)")
    if "nodes" in info:
        kept = f" of {info['program_nodes']:,}" if info["filtered"] else ""
        print(f"nodes       {info['nodes']:,}{kept} ({info['template_nodes']} per group)")
        kept = f" of {info['program_beams']:,}" if info["filtered"] else ""
        print(f"beams       {info['beams']:,}{kept} ({info['beam_patterns']} beam-patterns)")
    else:
        print(f"nodes       {info['counts_method']}")
    if "group_map" in info:
        print(f"groups by   {info['group_map']['kind']} map ({info['group_map']['note']})")
    for name, s in info.get("similarities", {}).items():
        cum = " (given cumulatively)" if s["cumulative"] else ""
        print(f"{name}           {s['kind']}{cum}")
    if "bounds" in info:
        approx = "" if info["bounds"]["exact"] else "  (approximate: sampled groups)"
        print(f"bounds      {_fmt(info['bounds']['min'])} .. {_fmt(info['bounds']['max'])}{approx}")
    print(f"mean radius {info['mean_radius']:.6g}")
    for key in ("area", "volume"):
        if key in info:
            print(f"{key:<11} {info[key]:.9g}")
    if "centroid" in info:
        print(f"centroid    {_fmt(info['centroid'])}")
    if info.get("clean") is False:
        print("not clean   some beams or balls overlap elements they share no ball with: area, volume and meshes "
              "assume a clean lattice (ple check lists them)")
    return 0


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
