"""Where CLGs come from: a ``ple-clg/1`` file, a program defining ``clg(**params)`` (same inputs and
slider conventions as ``lattice()``), or a CLG preset (``presets/clg/``)."""

from __future__ import annotations

from pathlib import Path

from ..clg import model
from ..clg.field import FieldSolid
from ..clg.ir import clg_from_dict
from ..clg.model import CLG
from ..errors import PleError, echo
from ..io.inputs import check_input_file, read_input_file, read_json
from .presets import preset_dir
from .runner import CLI_HINTS, DEFAULT_TIMEOUT, Hints, Job, check_timeout
from .runtime import API, Program, parse_params, run_source

MAX_JSON_DEPTH = 256  # a ple-clg/1 file's JSON nesting: its pattern, chunk expressions and nested materials

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
        check_input_file(p, f"CLG {p.suffix} file")  # a folder, FIFO or device is named as such
        return p
    plain = source and all(c.isalnum() or c in "_-" for c in source) and not source.startswith(("_", "-"))
    for ext in (".py", ".json") if plain else ():  # only plain names: a name cannot reach outside the presets
        entry = clg_preset_folder() / (source + ext)
        if entry.is_file():
            return Path(str(entry))
    raise PleError(f"{echo(source)} is neither a .py CLG program, a .json ple-clg/1 file, nor a CLG preset "
                   f"(presets: {', '.join(clg_preset_names())})")


def load_clg(source: str, params: list[str] | dict | None = None) -> CLG:
    """The CLG of a ``ple-clg/1`` file, a program or a preset, with ``NAME=VALUE`` params."""
    path = resolve_clg(source)
    if path.suffix == ".json":
        if params:
            raise PleError(f"{source}: a .json CLG file has no parameters")
        data = read_json(path, "ple-clg/1 file", MAX_JSON_DEPTH)  # size, UTF-8, depth, digits (ple.io.inputs)
        try:
            return clg_from_dict(data)
        except PleError as exc:
            raise PleError(f"{source}: {exc}") from None
    raw = read_input_file(path, "CLG program file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PleError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    prog = compile_clg_program(text, str(path))
    values = parse_params(prog, params) if isinstance(params, list) else dict(params or {})
    return prog.run(**values)


def run_clg(source: str, params=None, timeout: float | None = DEFAULT_TIMEOUT, memory: int | None = None,
            hints: Hints = CLI_HINTS) -> CLG:
    """``load_clg`` with a program contained in a child process (``ple.program.runner``): at most
    ``timeout`` seconds and ``memory`` bytes; ``sys.exit``, ``os._exit`` and any exception become one
    error naming the program. A ``ple-clg/1`` file is data and loads in-process."""
    check_timeout(timeout)
    path = resolve_clg(source)
    if path.suffix == ".json":
        return load_clg(source, params)
    clg = Job(lambda: load_clg(source, params), str(path), timeout, memory, what="the CLG program",
              hints=hints).result()
    if not isinstance(clg, CLG):  # pragma: no cover - load_clg checks it in the child
        raise PleError(f"{path}: clg() must return a CLG")
    return clg
