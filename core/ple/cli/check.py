"""``ple check LATTICE [--region R] [--json] [--min-feature MM] [--max-slenderness X]``: design rules
for printing (clean, thinnest beam, smallest gap, slenderness, dangling beams, isolated balls,
components). Exit 0 when every rule holds, 1 when some fail (a report, not an error), 2 for bad input."""

from __future__ import annotations

import json

from ..measure.check import check_lattice
from .common import add_lattice_args, lattice_from_args

NAMES = {"clean": "clean (no overlapping non-incident elements)", "thinnest_beam": "thinnest beam diameter",
         "smallest_gap": "smallest gap between non-incident elements", "slenderness": "beam slenderness L/d",
         "dangling_beams": "dangling beams (ball with one beam)", "isolated_balls": "isolated balls",
         "components": "connected components"}


def register(sub) -> None:
    p = sub.add_parser("check", help="design rules: clean, thinnest beam, gaps, slenderness, dangling, components")
    add_lattice_args(p)
    p.add_argument("--region", metavar="I0:I1,J0:J1,K0:K1", help="check only this index region")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--min-feature", type=float, metavar="MM",
                   help="smallest printable feature: thinnest beam diameter and smallest gap (model units)")
    p.add_argument("--max-slenderness", type=float, metavar="X", help="largest beam length / diameter")
    p.set_defaults(func=run)


def run(args) -> int:
    lat = lattice_from_args(args)
    report = check_lattice(lat, args.region, args.min_feature, args.max_slenderness)
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        kept = " (kept by its filter)" if report["filtered"] else ""
        print(f"region {report['region']}: {report['nodes']:,} balls, {report['beams']:,} beams{kept}")
        for key, rule in report["rules"].items():
            print(f"{'ok  ' if rule['ok'] else 'FAIL'} {NAMES[key]}: {_value(key, rule)}")
            if not rule["ok"]:
                for w in rule["worst"][:5]:
                    print(f"       {_offender(w)}")
    return 0 if report["ok"] else 1


def _value(key: str, rule: dict) -> str:
    limit = f" (limit {rule['limit']:g})" if isinstance(rule.get("limit"), float) else ""
    if key == "clean":
        pairs = rule["value"]
        kinds = ", ".join(f"{n:,} {k.replace('_', '–')}" for k, n in pairs.items() if n)
        return f"{rule['count']:,} unclean pairs" + (f" ({kinds})" if kinds else "")
    if key == "smallest_gap":
        if rule["value"] is None:
            return f"none closer than {rule['searched_within']:.4g}{limit}"
        return f"{rule['value']:.4g}{limit}"
    if key in ("thinnest_beam", "slenderness"):
        v = "no beams" if rule["value"] is None else f"{rule['value']:.4g}"
        return v + limit + (f", {rule['count']:,} beams beyond" if rule["count"] else "")
    return f"{rule['count']:,}"


def _offender(w: dict) -> str:
    parts = []
    for side in ("a", "b"):
        if side in w:
            (kind, idx), = w[side].items()
            parts.append(f"{kind} {tuple(idx)}")
    if parts:
        extra = f" depth {w['depth']:.3g}" if "depth" in w else ""
        copies = f", {w['count']:,} similar copies" if w.get("count", 1) > 1 else ""
        return f"{w.get('kind', '')} {' × '.join(parts)}{extra}{copies}".strip()
    (kind, idx), = ((k, v) for k, v in w.items() if k in ("ball", "beam"))
    return f"{kind} {tuple(idx)}" + (f" ({w['balls']} balls)" if "balls" in w else "")
