"""``ple batch PROGRAM --param NAME=SWEEP … --style S --format F --out DIR``: export variants."""

from __future__ import annotations

from ..app.batch import run_batch
from ..io.files import strict_json
from ..io.formats import FORMAT_NAMES
from ..meshing.styles import DEFAULT_STYLE, STYLE_NAMES
from .common import add_program_limits, limits


def register(sub) -> None:
    p = sub.add_parser("batch", help="mesh and export every variant of a parameter sweep")
    p.add_argument("lattice", metavar="PROGRAM", help="a program .py or a preset name")
    p.add_argument("--param", action="append", default=[], metavar="NAME=SWEEP",
                   help="value, v1,v2,… or lo:hi:n (repeatable; variants are the Cartesian product)")
    p.add_argument("--style", default=DEFAULT_STYLE, choices=STYLE_NAMES)
    p.add_argument("--levels", type=int, help="refinement levels for --style refined")
    p.add_argument("--format", default="stl", choices=FORMAT_NAMES)
    p.add_argument("--region", help="I0:I1,J0:J1,K0:K1 to mesh (default: whole lattice)")
    p.add_argument("--jobs", "--workers", dest="jobs", type=int,
                   help="workers of the embedded Dask cluster (default: all cores)")
    p.add_argument("--scheduler", default="local", metavar="S",
                   help="local (an embedded Dask cluster, default), sync (this process) or a Dask scheduler "
                        "address tcp://HOST:PORT")
    p.add_argument("--out", required=True, help="output folder (manifest.json is written there)")
    add_program_limits(p)
    p.set_defaults(func=run)


def run(args) -> int:
    result = run_batch(args.lattice, args.param, args.out, args.style, args.format, args.levels, args.region,
                       args.jobs, limits=limits(args), scheduler=args.scheduler)
    print(strict_json(result, "the batch summary", indent=1))
    return 2 if result["failed"] else 0  # a variant the program rejects is bad input
