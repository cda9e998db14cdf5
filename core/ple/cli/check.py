"""``ple check LATTICE [--region R] [--json] [--min-feature MM] [--max-slenderness X]``: design rules
for printing (clean, thinnest beam, smallest gap, slenderness, dangling beams, isolated balls,
components). Exit 0 when every rule holds, 1 when some fail (a report, not an error), 2 for bad input."""

from __future__ import annotations

from ..io.files import strict_json
from ..measure.check import check_lattice, rule_lines
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("check", help="design rules: clean, thinnest beam, gaps, slenderness, dangling, components")
    add_lattice_args(p)
    p.add_argument("--region", metavar="I0:I1,J0:J1,K0:K1", help="check only this index region")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--min-feature", type=float, metavar="MM",
                   help="smallest printable feature: thinnest beam diameter and smallest gap (model units)")
    p.add_argument("--max-slenderness", type=float, metavar="X", help="largest beam length / diameter")
    p.add_argument("--max-pairs", type=float, metavar="N",
                   help="most candidate pairs the clean rule tests (default: 256 per element, at least 1e7); "
                        "counted before testing")
    p.set_defaults(func=run)


def run(args) -> int:
    lat = lattice_from_args(args)
    report = check_lattice(lat, args.region, args.min_feature, args.max_slenderness, args.max_pairs)
    if args.json:
        print(strict_json(report, "the check report", indent=1))
    else:
        kept = " (kept by its filter)" if report["filtered"] else ""
        print(f"region {report['region']}: {report['nodes']:,} balls, {report['beams']:,} beams{kept}")
        for _, ok, text, worst in rule_lines(report):
            print(f"{'ok  ' if ok else 'FAIL'} {text}")
            for line in worst:
                print(f"       {line}")
    return 0 if report["ok"] else 1
