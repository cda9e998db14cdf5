"""Where lattices come from: a program ``.py``, an IR ``.json`` or a preset name, with inputs."""

from __future__ import annotations

from pathlib import Path

from ..errors import PleError, echo
from ..io.inputs import check_input_file
from ..io.irfile import load_ir
from ..model.lattice import Lattice
from .presets import preset_names, preset_path
from .runtime import load_program_file, parse_params


def resolve_source(source: str) -> Path:
    """A program ``.py``, an IR ``.json`` or a preset name, to a file path."""
    p = Path(source)
    if p.suffix in (".py", ".json"):
        check_input_file(p, f"{p.suffix} file")
        return p
    found = preset_path(source)
    if found is None:
        raise PleError(f"{echo(source)} is neither a .py program, a .json lattice file, nor a preset "
                       f"(presets: {', '.join(preset_names())})")
    return found


def load_lattice(source: str, params: list[str] | dict | None = None) -> Lattice:
    """Build the lattice of a program file, IR file or preset, with ``NAME=VALUE`` params."""
    path = resolve_source(source)
    if path.suffix == ".json":
        if params:
            raise PleError(f"{source}: a .json lattice file has no parameters")
        return load_ir(path)
    prog = load_program_file(path)
    values = parse_params(prog, params) if isinstance(params, list) else dict(params or {})
    return prog.run(**values)
