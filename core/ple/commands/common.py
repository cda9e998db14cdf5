"""Argument helpers shared by sub-commands (not itself a command)."""

from __future__ import annotations

import argparse
import zipfile

import numpy as np

from ..budget import add_budget_args, max_memory
from ..files import atomic_path
from ..filters import evaluate_lattice  # noqa: F401 - re-exported for the commands
from ..lattice import Lattice
from ..runner import DEFAULT_TIMEOUT, run_program
from ..schema import load_npy  # noqa: F401 - re-exported for the commands


def register(sub) -> None:  # this module adds no command
    return None


def add_lattice_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("lattice", metavar="LATTICE", help="a program .py, an IR .json, or a preset name")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="set a program input (repeatable)")
    add_program_limits(p)


def add_program_limits(p: argparse.ArgumentParser) -> None:
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, metavar="SECONDS",
                   help=f"time limit of the program (default {DEFAULT_TIMEOUT:g} s)")
    add_budget_args(p)


def lattice_from_args(args) -> Lattice:
    """The lattice of a command's LATTICE, its program contained (``ple.runner``)."""
    return run_program(args.lattice, args.param, args.timeout, max_memory(args))


def contained(args):
    """``source, params -> Lattice`` with the command's limits (for --coarse lattices)."""
    return lambda source, params=None: run_program(source, params, args.timeout, max_memory(args))


def save_npz(path, arrays: dict) -> None:
    """Write arrays to ``path`` (.npz, as ``np.savez``) atomically. The zip is closed before its
    file, also when interrupted (``np.savez`` on a handle leaves that to the garbage collector)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh, zipfile.ZipFile(fh, "w", allowZip64=True) as zf:
        for name, arr in arrays.items():
            with zf.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(arr), allow_pickle=False)


