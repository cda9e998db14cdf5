"""``ple bench NAME``: benchmarks (modules of ``ple.bench``), printing JSON."""

from __future__ import annotations

import importlib
import json
import math
import pkgutil

from .. import bench
from ..errors import PleError
from ..io.files import atomic_write_text, check_output_file


def register(sub) -> None:
    p = sub.add_parser("bench", help="run a benchmark and print JSON")
    bsub = p.add_subparsers(dest="bench", metavar="BENCH")
    bsub.required = True
    for info in sorted(pkgutil.iter_modules(bench.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{bench.__name__}.{info.name}")
        bp = bsub.add_parser(info.name, help=(module.__doc__ or "").strip().splitlines()[0])
        module.add_arguments(bp)
        bp.add_argument("--out", help="also write the JSON to this file")
        bp.set_defaults(func=_runner(module, bp))


def _check_numbers(args, parser) -> None:
    """Every numeric option finite and not negative; at least 1 where its default is (counts,
    repeats, sizes): checked before the benchmark runs, not after minutes of it."""
    for name, value in vars(args).items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or name == "seed":
            continue
        default = parser.get_default(name)
        least = 1 if isinstance(default, (int, float)) and default >= 1 else 0
        if not math.isfinite(value) or value < least:
            raise PleError(f"--{name.replace('_', '-')} {value}: expected a number of at least {least}")


def _runner(module, parser):
    def run(args) -> int:
        _check_numbers(args, parser)
        if args.out:
            check_output_file(args.out)
        result = module.run(args)
        text = json.dumps(result, indent=1)
        print(text)
        if args.out:
            atomic_write_text(args.out, text + "\n")
        return 0
    return run
