"""The ``ple`` command line. Sub-commands live in the other ``ple.cli.*`` modules, each with a
``register(subparsers)`` that adds its parser and sets ``func(args) -> int``.

User mistakes (PleError) print one line on stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from .. import cli
from ..errors import PleError

NOT_COMMANDS = {"main", "common", "__main__"}  # the modules of ple.cli that add no sub-command


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ple", description="PLE — the Programmed Lattice Editor.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(cli.__path__), key=lambda m: m.name):
        if info.name not in NOT_COMMANDS:
            importlib.import_module(f"{cli.__name__}.{info.name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PleError as exc:
        print(f"ple {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`
        sys.stderr.close()
        return 0
    except KeyboardInterrupt:
        print(f"ple {args.command}: interrupted", file=sys.stderr)
        return 130


def run() -> None:
    sys.exit(main())


if __name__ == "__main__":
    run()
