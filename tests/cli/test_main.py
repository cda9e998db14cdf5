"""The ``ple`` parser: one module per sub-command, named as the command, loaded only when used."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys

from ple.cli.main import build_parser, command_names


def test_each_command_module_registers_its_own_name():
    for name in command_names():
        sub = argparse.ArgumentParser().add_subparsers(dest="command")
        importlib.import_module(f"ple.cli.{name}").register(sub)
        assert list(sub.choices) == [name]
    assert set(build_parser()._subparsers._group_actions[0].choices) == set(command_names())


def test_a_command_imports_only_what_it_uses():
    """``ple info`` needs neither trimesh nor the benchmarks (they cost a second at start-up)."""
    code = ("import sys; from ple.cli.main import main; main(['presets']); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'trimesh' or m.startswith('ple.bench')"
            " or m.startswith('ple.cli.mesh')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_help_lists_every_command_with_its_own_help():
    """``ple --help`` reads each sub-command's help from its source; it must be the help the
    module's own ``register`` gives its parser."""
    from ple.cli.main import command_help

    for name in command_names():
        sub = argparse.ArgumentParser().add_subparsers(dest="command")
        importlib.import_module(f"ple.cli.{name}").register(sub)
        action = next(a for a in sub._choices_actions if a.dest == name)
        assert command_help(name) == action.help, name


HEAVY = ("trimesh", "scipy", "ple.bench", "ple.program.runtime", "ple.meshing", "ple.filters", "ple.queries")


def test_help_and_presets_import_no_heavy_module():
    """Start-up (issue 14): ``ple --help`` and ``ple presets`` import none of the heavy layers
    (their median start-up is measured by ``ple bench startup``)."""
    for argv in (["--help"], ["presets"]):
        code = (f"import sys\nfrom ple.cli.main import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
                f"print('|', sorted(m for m in sys.modules if m.startswith({HEAVY!r})))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        assert out.strip().splitlines()[-1] == "| []", (argv, out[-300:])
