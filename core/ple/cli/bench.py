"""``ple bench NAME``: benchmarks (modules of ``ple.bench``), printing JSON."""

from __future__ import annotations

import importlib
import json
import pkgutil

from .. import bench
from ..io.files import atomic_write_text


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
        bp.set_defaults(func=_runner(module))


def _runner(module):
    def run(args) -> int:
        result = module.run(args)
        text = json.dumps(result, indent=1)
        print(text)
        if args.out:
            atomic_write_text(args.out, text + "\n")
        return 0
    return run
