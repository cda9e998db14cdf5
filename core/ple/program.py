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
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from .errors import PleError
from .geometry import Pt, Vec
from .lattice import Lattice
from .similarity import Identity, Rotation, Scaling, Screw, Similarity, Swirl, Translation


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
}


def _extra_api() -> dict:
    """More of the API in a program's scope, so programs need no imports (and run unchanged
    inside the Blender extension, where the core is vendored): filters (thesis §9) and
    BeCOTS fields, lattices and stacks (§4, §6.3)."""
    from . import becots, filters, implicit
    return {"Stencil": filters.Stencil, "LiL": filters.LiL, "FilteredLattice": filters.FilteredLattice,
            "ImplicitFilter": implicit.ImplicitFilter, "TPMSField": implicit.TPMSField,
            "FourierField": implicit.FourierField, "BeCOTSField": becots.BeCOTSField,
            "becots_lattice": becots.becots_lattice, "stack_lattice": becots.stack_lattice,
            "set_field": becots.set_field}


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
                raise PleError(f"{self.name}: input {p.name!r} of lattice() needs a default value")
            rng = p.annotation if isinstance(p.annotation, Range) else None
            out.append(Param(p.name, p.default, rng))
        return out

    def run(self, **params) -> Lattice:
        """Call ``lattice(**params)``; errors inside the program become PleError."""
        known = {p.name: p for p in self.parameters()}
        for name in params:
            if name not in known:
                raise PleError(f"{self.name}: unknown parameter {name!r} (inputs: {', '.join(known) or 'none'})")
        try:
            lat = self.function(**params)
        except PleError as exc:
            raise PleError(f"{self.name}: {exc}") from None
        except MemoryError:
            raise  # reported with the memory limit (ple.runner, ple.cli)
        except Exception as exc:  # the program is user code: report where it failed
            line = _program_line(exc, self.name)
            raise PleError(f"{self.name}{line}: program raised {type(exc).__name__}: {exc}") from None
        if not isinstance(lat, Lattice):
            raise PleError(f"{self.name}: lattice() must return a Lattice, got {type(lat).__name__}")
        lat.validate()
        return lat


def _program_line(exc: BaseException, filename: str) -> str:
    for frame in reversed(traceback.extract_tb(exc.__traceback__)):
        if frame.filename == filename:
            return f":{frame.lineno}"
    return ""


def _program_builtins() -> dict:
    """Builtins for programs. When this core is vendored under another package name (inside
    the Blender extension), ``import ple...`` in a program resolves to this very package."""
    names = dict(vars(builtins))
    if __package__ == "ple":
        return names
    real = builtins.__import__

    def vendored_import(name, globals=None, locals=None, fromlist=(), level=0):
        if level == 0 and (name == "ple" or name.startswith("ple.")):
            module = real(__package__ + name[3:], globals, locals, fromlist, level)
            return module if fromlist else sys.modules[__package__]
        return real(name, globals, locals, fromlist, level)

    names["__import__"] = vendored_import
    return names


def compile_program(source: str, name: str = "<program>") -> Program:
    """Compile program text; a syntax error or a missing ``lattice`` names the problem."""
    try:
        code = compile(source, name, "exec", dont_inherit=True)  # not this module's future annotations
    except SyntaxError as exc:
        raise PleError(f"{name}:{exc.lineno}: syntax error: {exc.msg}") from None
    ns: dict = {**API, **_extra_api()}
    ns["__builtins__"] = _program_builtins()  # vendored core: "import ple" means this package
    ns["__name__"] = "ple_program"
    try:
        exec(code, ns)  # noqa: S102 - programs are trusted code by design (SPEC §9)
    except Exception as exc:
        raise PleError(f"{name}{_program_line(exc, name)}: program raised {type(exc).__name__}: {exc}") from None
    if not callable(ns.get("lattice")):
        raise PleError(f"{name}: a program must define a function lattice(...)")
    return Program(source, name, ns)


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
        raise PleError(f"parameter {param.name}: {text!r} is not a valid {kind.__name__}") from None


def parse_params(program: Program, assignments: list[str]) -> dict:
    """Parse ``NAME=VALUE`` strings against a program's inputs."""
    known = {p.name: p for p in program.parameters()}
    out = {}
    for a in assignments:
        if "=" not in a:
            raise PleError(f"--param {a!r}: expected NAME=VALUE")
        name, value = a.split("=", 1)
        name = name.strip()
        if name not in known:
            raise PleError(f"--param {name}: unknown parameter (inputs: {', '.join(known) or 'none'})")
        out[name] = parse_param_value(known[name], value)
    return out


# ----- presets and sources ------------------------------------------------------------------
def preset_dir():
    return resources.files(f"{__package__}.presets")  # also when vendored inside the Blender extension


def preset_names() -> list[str]:
    names = []
    for entry in preset_dir().iterdir():
        if entry.name.endswith((".py", ".json")) and not entry.name.startswith("_"):
            names.append(entry.name.rsplit(".", 1)[0])
    return sorted(names)


def preset_path(name: str) -> Path | None:
    """The file of a preset; only plain names, so a name cannot reach outside the presets."""
    if not name or not all(c.isalnum() or c in "_-" for c in name) or name.startswith(("_", "-")):
        return None
    for ext in (".py", ".json"):
        entry = preset_dir() / (name + ext)
        if entry.is_file():
            return Path(str(entry))
    return None


def preset_description(name: str) -> str:
    path = preset_path(name)
    if path is None:
        raise PleError(f"unknown preset {name!r}")
    if path.suffix == ".json":
        return str(json.loads(path.read_text()).get("description", ""))
    return load_program_file(path).description


def load_program_file(path: Path) -> Program:
    from .schema import read_input_file

    raw = read_input_file(path, "program file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PleError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    return compile_program(text, str(path))


def resolve_source(source: str) -> Path:
    """A program ``.py``, an IR ``.json`` or a preset name, to a file path."""
    p = Path(source)
    if p.suffix in (".py", ".json"):
        from .schema import check_input_file

        check_input_file(p, f"{p.suffix} file")
        return p
    found = preset_path(source)
    if found is None:
        raise PleError(f"{source!r} is neither a .py program, a .json lattice file, nor a preset "
                       f"(presets: {', '.join(preset_names())})")
    return found


def load_lattice(source: str, params: list[str] | dict | None = None) -> Lattice:
    """Build the lattice of a program file, IR file or preset, with ``NAME=VALUE`` params."""
    from .ir import load_ir  # local: ir imports program-free modules only

    path = resolve_source(source)
    if path.suffix == ".json":
        if params:
            raise PleError(f"{source}: a .json lattice file has no parameters")
        return load_ir(path)
    prog = load_program_file(path)
    values = parse_params(prog, params) if isinstance(params, list) else dict(params or {})
    return prog.run(**values)
