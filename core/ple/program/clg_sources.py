"""Where CLGs come from: a ``ple-clg/1`` file, a program defining ``clg(**params)`` (same inputs and
slider conventions as ``lattice()``), or a CLG preset (``presets/clg/``)."""

from __future__ import annotations

import json
from pathlib import Path

from ..clg import model
from ..clg.field import FieldSolid
from ..clg.ir import clg_from_dict
from ..clg.model import CLG
from ..errors import PleError
from .presets import preset_dir
from .runtime import API, Program, parse_params, run_source

CLG_API = {"CLG": CLG, "Ball": model.Ball, "Beam": model.Beam, "HollowBeam": model.HollowBeam,
           "ExtendedHub": model.ExtendedHub, "Connector": model.Connector, "Union": model.Union,
           "Intersection": model.Intersection, "Difference": model.Difference, "Chunk": model.Chunk,
           "Material": model.Material, "FieldSolid": FieldSolid}


class CLGProgram(Program):
    """A program whose entry point is ``clg(**params)``."""

    @property
    def function(self):
        return self.namespace["clg"]

    def run(self, **params) -> CLG:
        out = self.call(**params)
        if not isinstance(out, CLG):
            raise PleError(f"{self.name}: clg() must return a CLG, got {type(out).__name__}")
        return out


def compile_clg_program(source: str, name: str = "<program>") -> CLGProgram:
    return CLGProgram(source, name, run_source(source, name, API | CLG_API, "clg", "a CLG program"))


def clg_preset_folder():
    """``presets/clg`` of the installed package, or of this checkout (core/ple/… → presets/clg)."""
    folder = preset_dir() / "clg"
    if folder.is_dir():
        return folder
    return Path(__file__).resolve().parents[3] / "presets" / "clg"


def clg_preset_names() -> list[str]:
    folder = clg_preset_folder()
    if not folder.is_dir():
        return []
    return sorted(e.name.rsplit(".", 1)[0] for e in folder.iterdir()
                  if e.name.endswith((".py", ".json")) and not e.name.startswith("_"))


def resolve_clg(source: str) -> Path:
    p = Path(source)
    if p.suffix in (".py", ".json"):
        if not p.is_file():
            raise PleError(f"{source}: no such file")
        return p
    for ext in (".py", ".json"):
        entry = clg_preset_folder() / (source + ext)
        if entry.is_file():
            return Path(str(entry))
    raise PleError(f"{source!r} is neither a .py CLG program, a .json ple-clg/1 file, nor a CLG preset "
                   f"(presets: {', '.join(clg_preset_names())})")


def load_clg(source: str, params: list[str] | dict | None = None) -> CLG:
    """The CLG of a ``ple-clg/1`` file, a program or a preset, with ``NAME=VALUE`` params."""
    path = resolve_clg(source)
    if path.suffix == ".json":
        if params:
            raise PleError(f"{source}: a .json CLG file has no parameters")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise PleError(f"{source}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
        return clg_from_dict(data)
    prog = compile_clg_program(path.read_text(), str(path))
    values = parse_params(prog, params) if isinstance(params, list) else dict(params or {})
    return prog.run(**values)
