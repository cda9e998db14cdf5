"""The ``ple`` command line. Sub-commands live in the other ``ple.cli.*`` modules, each with a
``register(subparsers)`` that adds its parser and sets ``func(args) -> int``.

User mistakes (PleError) print one line on stderr and exit with status 2.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import importlib.util
import os
import pkgutil
import re
import sys
from pathlib import Path

from .. import cli
from ..errors import ECHO_LIMIT, PleError, cut
from ..io.files import check_apart, install_signal_handlers, is_user_oserror, oserror_message, restore_signal_handlers

NOT_COMMANDS = {"main", "common", "__main__"}  # the modules of ple.cli that add no sub-command


def command_names() -> list[str]:
    """The sub-commands: one module of ``ple.cli`` each, named as the command (found without
    importing them, so that a command pays only for the modules it uses)."""
    return sorted(m.name for m in pkgutil.iter_modules(cli.__path__) if m.name not in NOT_COMMANDS)


class Parser(argparse.ArgumentParser):
    """The parser of ``ple`` and of its sub-commands (argparse makes sub-parsers of the parent's
    class). A value that starts with a minus sign and a digit is a value, not an option, so vector
    options take negative first values in the space form (``--bounds -0.5,-0.5,-0.5,0.5,0.5,0.5``,
    ``--view -30,20``, ``--region -2:,0:1,0:1``): argparse itself takes only a whole negative
    number (``-0.5``) for a value. No option of ``ple`` looks like a number; tested over every
    option that takes a value (``tests/cli/test_vector_options.py``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message: str):
        """argparse's usage error, every value it quotes cut (``ple.errors.cut``): an invalid
        choice of 1 MB is one short line."""
        long_quote = "'([^']{" + str(ECHO_LIMIT + 1) + ",})'"
        super().error(re.sub(long_quote, lambda m: f"'{cut(m.group(1))}'", message))


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``only`` (the sub-command about to run, imported with what it uses); with no
    sub-command, the list of them with their one-line help read from their source, none
    imported (``ple --help`` starts at once)."""
    parser = Parser(prog="ple", description="PLE — the Programmed Lattice Editor.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in command_names():
        if only is None:
            sub.add_parser(name, help=command_help(name))
        elif name == only:
            importlib.import_module(f"{cli.__name__}.{name}").register(sub)
    return parser


def command_help(name: str) -> str:
    """The ``help=`` a sub-command's module gives its parser (``sub.add_parser(name, help=…)``), read
    with ``ast`` without importing the module; its docstring's first line if it gives none."""
    spec = importlib.util.find_spec(f"{cli.__name__}.{name}")
    tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "add_parser"
                and node.args and isinstance(node.args[0], ast.Constant) and node.args[0].value == name):
            for kw in node.keywords:
                if kw.arg == "help" and isinstance(kw.value, ast.Constant):
                    return str(kw.value.value)
    doc = (ast.get_docstring(tree) or "").strip()
    return doc.splitlines()[0] if doc else ""


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first if first in command_names() else None)
    args = parser.parse_args(argv)
    try:
        check_paths(args)
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
    except OSError as exc:  # a full disk, a read-only file system, … outside a file writer (a folder, a marker)
        if not is_user_oserror(exc):
            raise
        print(f"ple {args.command}: error: {oserror_message(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM/SIGHUP (io.files.Terminated)
        print(f"ple {args.command}: interrupted", file=sys.stderr)
        return 128 + getattr(exc, "signum", 2)


OUTPUTS = ("out", "parts")  # the arguments a command writes, unless its parser sets ``outputs``


def check_paths(args) -> None:
    """The one check of every command's paths before any work: no output may overwrite an input
    (``ple.io.files.check_apart``). The outputs are the arguments named by the parser's
    ``outputs`` default (``--out`` and ``--parts``); every other argument whose text (or the text
    after its last ``=``: ``--param file=F``, ``--implicit fourier:file=F``) names an existing
    path is an input."""
    names = getattr(args, "outputs", OUTPUTS)
    outputs = {f"--{n.replace('_', '-')}": getattr(args, n) for n in names if getattr(args, n, None)}
    inputs: dict = {}
    for key, value in vars(args).items():
        if key in names or key in ("func", "outputs", "command"):
            continue
        for n, text in enumerate(value if isinstance(value, list) else [value]):
            if not isinstance(text, str):
                continue
            flag = key if key in ("lattice", "source", "mesh", "parts") else f"--{key.replace('_', '-')}"
            for cand in {text, text.rpartition("=")[2]}:
                if cand and os.path.lexists(cand):
                    inputs[f"{flag}{f'[{n}]' if isinstance(value, list) else ''}"] = cand
    check_apart(outputs, inputs)


def run() -> None:
    """The console script ``ple``: SIGTERM and SIGHUP unwind like Ctrl-C (temporaries removed)
    while it runs; the process's handlers are restored after it (``main`` itself sets no
    process-wide state)."""
    old = install_signal_handlers()
    try:
        code = main()
    except KeyboardInterrupt as exc:  # before a command runs (its modules still loading): nothing was written
        print("ple: interrupted", file=sys.stderr)
        code = 128 + getattr(exc, "signum", 2)
    finally:
        restore_signal_handlers(old)
    sys.exit(code)


if __name__ == "__main__":
    run()
