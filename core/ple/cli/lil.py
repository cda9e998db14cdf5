"""``ple lil FINE --coarse C1 [--coarse C2 …] [--out F.npz|DIR]``: Lattice-in-Lattice (thesis §9).

A fine node survives when it interferes with the coarse lattice; several ``--coarse`` cascade
from finest to coarsest (F filtered by C1 filtered by C2, thesis Fig. 9.3). Output arrays as
``ple eval`` for the surviving nodes and beams; without ``--out`` only the counts are printed.
"""

from __future__ import annotations

from ..errors import PleError
from .common import add_lattice_args, lattice_from_args, parse_stencil
from .filter import add_output_args, build, write


def register(sub) -> None:
    p = sub.add_parser("lil", help="Lattice-in-Lattice filter (cascaded with several --coarse)")
    add_lattice_args(p)
    p.add_argument("--stencil", action="append", default=[], metavar="S",
                   help="also apply an index stencil to the fine lattice (see ple filter)")
    add_output_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    if not args.coarse:
        raise PleError("give at least one --coarse lattice")
    for s in args.stencil:
        parse_stencil(s)  # fail early on a bad stencil
    return write(args, build(args, lattice_from_args(args), []))
