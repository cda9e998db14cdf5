"""The ``ple`` command line. Sub-commands live in ``ple.commands.*`` modules, each with a
``register(subparsers)`` that adds its parser and sets ``func(args) -> int``.

User mistakes (PleError) print one line on stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from . import commands
from .errors import PleError
from .files import install_signal_handlers


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ple", description="PLE — the Programmed Lattice Editor.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    install_signal_handlers()  # SIGTERM/SIGHUP unwind like Ctrl-C: temporaries are removed
    try:
        return int(args.func(args) or 0)
    except PleError as exc:  # one line: control characters of the input (a key, a name) escaped
        msg = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(exc))
        print(f"ple {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"ple {args.command}: error: out of memory; choose a smaller --region or raise --max-memory",
              file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`
        sys.stderr.close()
        return 0
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM/SIGHUP (files.Terminated)
        print(f"ple {args.command}: interrupted", file=sys.stderr)
        return 128 + getattr(exc, "signum", 2)


def run() -> None:
    sys.exit(main())


if __name__ == "__main__":
    run()
