"""``ple ir LATTICE --out F.json``: the resolved IR (every U/V/W as its 4x4 matrix)."""

from __future__ import annotations

from ..io.irfile import save_ir
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("ir", help="write the resolved ple-lattice/1 file of a lattice")
    add_lattice_args(p)
    p.add_argument("--out", required=True, help="output .json")
    p.add_argument("--canonical", action="store_true",
                   help="keep canonical similarities and cumulative flags instead of matrices")
    p.set_defaults(func=run)


def run(args) -> int:
    lat = lattice_from_args(args)
    save_ir(lat, args.out, resolved=not args.canonical)
    print(f"wrote {args.out}")
    return 0
