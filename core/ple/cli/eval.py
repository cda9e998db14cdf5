"""``ple eval LATTICE [--region R] --out F.npz``: nodes and beams of a region."""

from __future__ import annotations

from ..errors import PleError
from ..io.files import save_npz
from ..model.budget import evaluation_bytes, region_beams, region_nodes, require
from .common import add_lattice_args, lattice_from_args, max_memory

MAX_EVAL_GROUPS = 50_000_000


def register(sub) -> None:
    p = sub.add_parser("eval", help="evaluate the nodes and beams of a region to .npz")
    add_lattice_args(p)
    p.add_argument("--region", help="I0:I1,J0:J1,K0:K1 (half-open); default: the whole lattice")
    p.add_argument("--out", required=True, help="output .npz")
    p.set_defaults(func=run)


def run(args) -> int:
    if not args.out.endswith(".npz"):
        raise PleError(f"--out {args.out}: expected a .npz file")
    lat = lattice_from_args(args)
    region = lat.region(args.region)
    if region.groups * len(lat.nodes) > MAX_EVAL_GROUPS:
        raise PleError(f"region {region} has {region.groups * len(lat.nodes):,} nodes; "
                       "choose a smaller --region (or stream with ple filter)")
    factor = 1 if lat.filter is None else 2  # a filter's masks and the kept copy
    require(factor * evaluation_bytes(lat, region), f"region {region} ({region_nodes(lat, region):,} nodes, "
            f"{region_beams(lat, region):,} beams)", max_memory(args), "choose a smaller --region")
    ev = lat.evaluate(region)
    save_npz(args.out, ev.arrays())
    print(f"wrote {args.out}: {len(ev.center):,} nodes, {len(ev.beam_nodes):,} beams")
    return 0
