"""Lattice programs (SPEC §4): Python files defining ``lattice(**params)``.

A program's keyword arguments are its exposed inputs; an annotation ``Range(lo, hi)``
gives a slider range, e.g. ``def lattice(thickness: Range(0.02, 0.2) = 0.0645)``. The
program runs with the API below already in scope (``Lattice``, ``Pt``, ``Vec`` and the
similarity constructors), so thesis Fig. 6.3 reads verbatim.
"""

from __future__ import annotations

import builtins
import inspect
import json
import math
import sys
import traceback
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..algebra.mobius import Cline, Mobius
from ..algebra.similarity import Identity, Rotation, Scaling, Screw, Similarity, Swirl, Translation
from ..algebra.vectors import Pt, Vec
from ..errors import PleError, cut, echo
from ..filters.base import FilteredLattice
from ..filters.implicit import FourierField, ImplicitFilter, TPMSField
from ..filters.lil import LiL
from ..filters.stencil import Stencil
from ..io.inputs import read_input_file
from ..model.becots import BeCOTSField
from ..model.becots_builders import becots_lattice, set_field, stack_lattice
from ..model.lattice import Lattice
from ..model.mobius import TMIMap, mobius_frames_lattice, mobius_lattice, with_control_frames
from ..model.planar import ShapeOntoCone, SteadyMap2, snap_corner
from ..model.warp import RectifiedWarp, rectified_warp


@dataclass(frozen=True)
class Range:
    """Slider range of a program input: ``lo <= value <= hi``."""

    lo: float
    hi: float
    step: float | None = None


@dataclass(frozen=True)
class Param:
    """An exposed program input: its name, default, optional range and kind."""

    name: str
    default: Any
    range: Range | None = None

    @property
    def kind(self) -> type:
        return type(self.default)


API = {
    "Lattice": Lattice, "Pt": Pt, "Vec": Vec, "Similarity": Similarity, "Identity": Identity,
    "Translation": Translation, "Rotation": Rotation, "Scaling": Scaling, "Swirl": Swirl,
    "Screw": Screw, "Range": Range, "math": math, "pi": math.pi,
    # filters (thesis §9) and BeCOTS fields, lattices and stacks (§4, §6.3): programs need no
    # imports, so they run unchanged inside the Blender extension where the core is vendored
    "Stencil": Stencil, "LiL": LiL, "FilteredLattice": FilteredLattice, "ImplicitFilter": ImplicitFilter,
    "TPMSField": TPMSField, "FourierField": FourierField, "BeCOTSField": BeCOTSField,
    "becots_lattice": becots_lattice, "stack_lattice": stack_lattice, "set_field": set_field,
    # Möbius patterns and TMI maps (§11)
    "Mobius": Mobius, "Cline": Cline, "TMIMap": TMIMap, "mobius_lattice": mobius_lattice,
    "mobius_frames_lattice": mobius_frames_lattice, "with_control_frames": with_control_frames,
    # rectified steady warps (§3.1–3.4)
    "RectifiedWarp": RectifiedWarp, "rectified_warp": rectified_warp,
    # five-point planar maps, shapes rolled onto cones, seamless snapping (§2.6.5, §4.3.2, §4.4.3)
    "SteadyMap2": SteadyMap2, "ShapeOntoCone": ShapeOntoCone, "snap_corner": snap_corner,
}
ROOT_PACKAGE = __package__.rsplit(".", 1)[0]  # "ple", or the vendored copy's full name in Blender


@dataclass
class Program:
    """A compiled program: its source, the ``lattice`` function and its parameters."""

    source: str
    name: str
    namespace: dict

    @property
    def function(self):
        return self.namespace["lattice"]

    @property
    def description(self) -> str:
        doc = self.namespace.get("__doc__") or ""
        return doc.strip().splitlines()[0] if doc.strip() else ""

    def parameters(self) -> list[Param]:
        out = []
        for p in inspect.signature(self.function).parameters.values():
            if p.kind not in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY):
                continue
            if p.default is inspect.Parameter.empty:
                raise PleError(f"{self.name}: input {echo(p.name)} of lattice() needs a default value")
            rng = p.annotation if isinstance(p.annotation, Range) else None
            out.append(Param(p.name, p.default, rng))
        return out

    def run(self, **params) -> Lattice:
        """Call ``lattice(**params)``; errors inside the program become PleError."""
        lat = self.call(**params)
        if not isinstance(lat, Lattice):
            raise PleError(f"{self.name}: lattice() must return a Lattice, got {type(lat).__name__}")
        lat.validate()
        return lat

    def call(self, **params):
        """The entry function called with checked inputs; errors inside the program become
        PleError naming the program's file and line (a MemoryError goes on to the limit's report)."""
        known = {p.name: p for p in self.parameters()}
        for name in params:
            if name not in known:
                raise PleError(f"{self.name}: unknown parameter {echo(name)} (inputs: {', '.join(known) or 'none'})")
        try:
            return self.function(**params)
        except PleError as exc:
            raise PleError(f"{self.name}: {exc}") from None
        except MemoryError:
            raise  # reported with the memory limit (ple.program.runner and the command line)
        except Exception as exc:  # the program is user code: report where it failed
            line = _program_line(exc, self.name)
            raise PleError(f"{self.name}{line}: program raised {type(exc).__name__}: {exc}") from None


def _program_line(exc: BaseException, filename: str) -> str:
    for frame in reversed(traceback.extract_tb(exc.__traceback__)):
        if frame.filename == filename:
            return f":{frame.lineno}"
    return ""


def _program_builtins() -> dict:
    """Builtins for programs. When this core is vendored under another package name (inside
    the Blender extension), ``import ple...`` in a program resolves to this very package."""
    names = dict(vars(builtins))
    if ROOT_PACKAGE == "ple":
        return names
    real = builtins.__import__

    def vendored_import(name, globals=None, locals=None, fromlist=(), level=0):
        if level == 0 and (name == "ple" or name.startswith("ple.")):
            module = real(ROOT_PACKAGE + name[3:], globals, locals, fromlist, level)
            return module if fromlist else sys.modules[ROOT_PACKAGE]
        return real(name, globals, locals, fromlist, level)

    names["__import__"] = vendored_import
    return names


def compile_program(source: str, name: str = "<program>") -> Program:
    """Compile program text; a syntax error or a missing ``lattice`` names the problem."""
    return Program(source, name, run_source(source, name, API, "lattice", "a program"))


def run_source(source: str, name: str, api: dict, entry: str, what: str) -> dict:
    """The namespace of program text run with ``api`` in scope; a syntax error, an error while
    running, or no callable ``entry`` names the problem (``what``: "a program", …)."""
    try:
        code = compile(source, name, "exec", dont_inherit=True)  # not this module's future annotations
    except SyntaxError as exc:
        raise PleError(f"{name}:{exc.lineno}: syntax error: {exc.msg}") from None
    ns: dict = dict(api)
    ns["__builtins__"] = _program_builtins()  # vendored core: "import ple" means this package
    ns["__name__"] = "ple_program"
    try:
        exec(code, ns)  # noqa: S102 - programs are trusted code by design (SPEC §9)
    except Exception as exc:
        raise PleError(f"{name}{_program_line(exc, name)}: program raised {type(exc).__name__}: {exc}") from None
    if not callable(ns.get(entry)):
        raise PleError(f"{name}: {what} must define a function {entry}(...)")
    return ns


@contextmanager
def trace_program(filename: str, local):
    """Trace the frames of code compiled as ``filename`` (a program) with ``local``, a
    ``sys.settrace`` local trace function; every other frame runs untraced, at full speed.
    The previous trace function is restored on the way out."""

    def outer(frame, event, arg):
        if frame.f_code.co_filename != filename:
            return None
        return local(frame, event, arg)

    old = sys.gettrace()
    sys.settrace(outer)
    try:
        yield
    finally:
        sys.settrace(old)


def parse_param_value(param: Param, text: str):
    """Convert ``--param NAME=VALUE`` text to the type of the input's default."""
    kind = param.kind
    try:
        if kind is bool:
            low = text.strip().lower()
            if low not in ("1", "0", "true", "false", "yes", "no"):
                raise ValueError
            return low in ("1", "true", "yes")
        if kind is int:
            return int(text)
        if kind is float:
            value = float(text)
            if not math.isfinite(value):
                raise ValueError
            return value
        if kind is str:
            return text
        return json.loads(text)
    except ValueError:
        raise PleError(f"parameter {param.name}: {echo(text)} is not a valid {kind.__name__}") from None


def parse_params(program: Program, assignments: list[str]) -> dict:
    """Parse ``NAME=VALUE`` strings against a program's inputs."""
    known = {p.name: p for p in program.parameters()}
    out = {}
    for a in assignments:
        if "=" not in a:
            raise PleError(f"--param {echo(a)}: expected NAME=VALUE")
        name, value = a.split("=", 1)
        name = name.strip()
        if name not in known:
            raise PleError(f"--param {cut(name)}: unknown parameter (inputs: {', '.join(known) or 'none'})")
        out[name] = parse_param_value(known[name], value)
    return out


def load_program_file(path: Path) -> Program:
    raw = read_input_file(path, "program file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PleError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    return compile_program(text, str(path))
