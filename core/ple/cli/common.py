"""Argument helpers shared by sub-commands (not itself a command): the lattice argument, the
limits of a program and of the work (``--timeout``, ``--max-memory``; docs/reliability.md), and
the small languages of ``--stencil`` and ``--implicit``."""

from __future__ import annotations

import argparse
import sys

from ..algebra.similarity import Translation
from ..errors import PleError, echo
from ..filters.body import MODES, OPEN_MODES, BodyFilter, SurfaceDistanceField, body_of
from ..filters.cleanup import cleanup
from ..filters.implicit import VARIANTS, Field, FourierField, ImplicitFilter, TPMSField
from ..filters.stencil import Stencil
from ..io.inputs import load_npy
from ..io.irfile import read_body
from ..model.budget import ENV, default_max_memory, parse_size
from ..model.grading import LinearGradient, RadiusField
from ..model.lattice import Lattice
from ..program.runner import DEFAULT_TIMEOUT, run_program


def add_lattice_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("lattice", metavar="LATTICE", help="a program .py, an IR .json, or a preset name")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="set a program input (repeatable)")
    add_program_limits(p)
    add_body_args(p)


def add_budget_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-memory", metavar="SIZE",
                   help=f"refuse work estimated beyond SIZE (e.g. 4G; default a quarter of RAM or ${ENV})")


def add_program_limits(p: argparse.ArgumentParser) -> None:
    p.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT, metavar="SECONDS",
                   help=f"time limit of the program (default {DEFAULT_TIMEOUT:g} s)")
    add_budget_args(p)


def max_memory(args=None) -> int:
    """The limit of a command: its ``--max-memory``, else the default (``ple.model.budget``)."""
    text = getattr(args, "max_memory", None)
    return parse_size(text) if text else default_max_memory()


def limits(args) -> tuple[float, int]:
    """(--timeout, --max-memory in bytes) of a command: the limits of each run of its program,
    in this process's child and on the workers of its job (``ple.app.jobs.Job.limits``)."""
    return args.timeout, max_memory(args)


def lattice_from_args(args) -> Lattice:
    """The lattice of a command's LATTICE, its program contained (``ple.program.runner``)."""
    lat = with_body_args(args, run_program(args.lattice, args.param, *limits(args)))
    if getattr(args, "skin", None) is not None:
        body_of(lat, "--skin")  # the body the skin lines: --body, or the lattice's own body filter
    if getattr(args, "cleanup", False):
        lat, report = cleanup(lat, getattr(args, "region", None), skin=getattr(args, "skin", None))
        print(report, file=sys.stderr)
    return lat


def contained(args):
    """``source, params -> Lattice`` with the command's limits (for --coarse lattices)."""
    return lambda source, params=None: run_program(source, params, *limits(args))


def add_body_args(p: argparse.ArgumentParser) -> None:
    """``--body MESH --fill MODE [--body-open winding]``: keep what fills a closed mesh (docs/body.md)."""
    p.add_argument("--body", metavar="MESH", help="fill a body: keep the nodes that fill this closed mesh "
                   "(STL, OBJ, PLY, 3MF, GLB)")
    p.add_argument("--fill", choices=MODES, default="inside",
                   help="with --body: inside (balls wholly inside), centroid (groups whose template centroid "
                        "is inside) or any (balls touching the body); default inside")
    p.add_argument("--body-open", choices=OPEN_MODES, default="error",
                   help="with --body: an open mesh is an error (default) or tested by winding numbers")
    p.add_argument("--grade", metavar="SPEC",
                   help="graded thickness: AX,AY,AZ:BX,BY,BZ:F0:F1 (radii x F0 at A to x F1 at B, linear) or "
                        "surface:DEPTH:F0:F1 (x F0 on the --body surface to x F1 at DEPTH from it)")
    p.add_argument("--cleanup", action="store_true",
                   help="remove dangling balls (degree <= 1, repeatedly) and every piece but the largest; "
                        "the counts go to stderr")
    p.add_argument("--skin", type=float, metavar="T",
                   help="with --body: a shell of thickness T inside the body; --cleanup keeps the beams ending "
                        "on it, and ple mesh unites it with the lattice into one solid (as ple skin)")


def with_body_args(args, lat: Lattice) -> Lattice:
    """``lat`` graded by ``--grade`` and filtered by ``--body``/``--fill`` when given (after its
    own filter; the filter sees the graded radii)."""
    body = None
    if getattr(args, "body", None) is not None:
        body = read_body(args.body, open=args.body_open, name=f"--body {args.body}")
    if getattr(args, "grade", None):
        lat = lat.copy()
        lat.set_radius_field(parse_grade(args.grade, body))
    if body is None:
        return lat
    return lat.with_filter(BodyFilter(body, args.fill))


def parse_grade(text: str, body=None) -> RadiusField:
    """``AX,AY,AZ:BX,BY,BZ:F0:F1`` (a linear gradient) or ``surface:DEPTH:F0:F1`` (with a body)."""
    parts = text.split(":")
    if parts[0] == "surface" and body is None:
        raise PleError(f"--grade {echo(text)}: a surface gradient needs --body")
    try:
        if parts[0] == "surface":
            if len(parts) != 4:
                raise ValueError
            return SurfaceDistanceField(body, float(parts[1]), float(parts[2]), float(parts[3]))
        if len(parts) != 4:
            raise ValueError
        a, b = ([float(x) for x in p.split(",")] for p in parts[:2])
        if len(a) != 3 or len(b) != 3:
            raise ValueError
        return LinearGradient(a, b, float(parts[2]), float(parts[3]))
    except PleError as exc:
        raise PleError(f"--grade {echo(text)}: {exc}") from None
    except ValueError:
        raise PleError(f"--grade {echo(text)}: expected AX,AY,AZ:BX,BY,BZ:F0:F1 or surface:DEPTH:F0:F1") from None


def parse_stencil(text: str) -> Stencil:
    """``NAME[:P|PxQxR][:W]`` (a named stencil) or a ``.npy`` file holding a Boolean array."""
    if text.endswith(".npy"):
        return Stencil(load_npy(text, "--stencil"))
    parts = text.split(":")
    try:
        period = [int(p) for p in parts[1].split("x")] if len(parts) > 1 else [4]
        width = int(parts[2]) if len(parts) > 2 else 1
    except ValueError:
        raise PleError(f"--stencil {echo(text)}: expected NAME[:PERIOD or PxQxR][:WIDTH]") from None
    if len(period) not in (1, 3) or len(parts) > 3:
        raise PleError(f"--stencil {echo(text)}: expected NAME[:PERIOD or PxQxR][:WIDTH]")
    return Stencil.named(parts[0], period[0] if len(period) == 1 else period, width)


def parse_implicit(text: str) -> ImplicitFilter:
    """``KIND[:key=value,...]`` with KIND a TPMS name or ``fourier`` (key ``file=F.npz``);
    keys ``cell`` (number or AxBxC), ``level``, ``variant`` (network|sheet) or a bare
    ``sheet``/``network``, ``origin`` (x/y/z, the placement's translation)."""
    kind, _, rest = text.partition(":")
    opts: dict[str, str] = {}
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        if not eq:
            if key in VARIANTS:
                opts["variant"] = key
                continue
            raise PleError(f"--implicit {echo(text)}: expected key=value, got {echo(item)}")
        opts[key.strip()] = value.strip()
    unknown = set(opts) - {"cell", "level", "variant", "origin", "file"}
    if unknown:
        raise PleError(f"--implicit {echo(text)}: unknown key(s) {', '.join(sorted(unknown))}")
    try:
        cell_parts = [float(x) for x in opts.get("cell", "1").split("x")]
        cell = cell_parts[0] if len(cell_parts) == 1 else cell_parts
        level = float(opts.get("level", "0"))
        origin = [float(x) for x in opts["origin"].split("/")] if "origin" in opts else None
    except ValueError:
        raise PleError(f"--implicit {echo(text)}: cell, level and origin must be numbers") from None
    placement = Translation(origin) if origin is not None else None
    if kind == "fourier":
        if "file" not in opts:
            raise PleError(f"--implicit {echo(text)}: a fourier field needs file=COEFFS.npz")
        field: Field = FourierField.load(opts["file"], cell, placement)
    else:
        field = TPMSField(kind, cell, placement)
    return ImplicitFilter(field, level, opts.get("variant", "network"))


def add_cluster_args(p: argparse.ArgumentParser, workers_help: str = "") -> None:
    """--parts, --scheduler, --workers: the command as a partitioned job (``ple.app.jobs``)."""
    p.add_argument("--parts", metavar="URL", help="write the result as parts of a job to a folder or fsspec URL "
                   "(a manifest records each part; a re-run skips the finished ones)")
    p.add_argument("--scheduler", default="local", metavar="S",
                   help="with --parts: local (an embedded Dask cluster, default), sync (this process) or a "
                        "Dask scheduler address tcp://HOST:PORT")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help=f"workers of the embedded local cluster{workers_help} (default: the cores)")


def report_job(summary: dict) -> int:
    """Print a job's summary; exit status 2 when some part failed (each named)."""
    for name, failure in summary["failed"].items():
        print(f"failed {name}: {failure['error']}", file=sys.stderr)
    print(f"{summary['written']} part(s) written, {summary['skipped']} already there, {len(summary['failed'])} "
          f"failed ({summary['seconds']:.1f} s); manifest {summary['manifest']}")
    return 2 if summary["failed"] else 0
