"""The preset library: lattice programs and IR files shipped as the package ``ple.presets``."""

from __future__ import annotations

import ast
import json
from importlib import resources
from pathlib import Path

from ..errors import PleError, echo
from ..io.inputs import read_input_file

ROOT_PACKAGE = __package__.rsplit(".", 1)[0]  # "ple", or the vendored copy's full name in Blender


def preset_dir():
    return resources.files(f"{ROOT_PACKAGE}.presets")  # also when vendored inside the Blender extension


MAX_NAME = 200  # characters: longer names are no preset (a file name holds at most 255 bytes)


def preset_names() -> list[str]:
    names = []
    for entry in preset_dir().iterdir():
        if entry.name.endswith((".py", ".json")) and not entry.name.startswith("_"):
            names.append(entry.name.rsplit(".", 1)[0])
    return sorted(names)


def preset_path(name: str) -> Path | None:
    """The file of a preset; only plain names, so a name cannot reach outside the presets."""
    if (not name or len(name) > MAX_NAME or not all(c.isalnum() or c in "_-" for c in name)
            or name.startswith(("_", "-"))):
        return None
    for ext in (".py", ".json"):
        entry = preset_dir() / (name + ext)
        if entry.is_file():
            return Path(str(entry))
    return None


def preset_description(name: str) -> str:
    path = preset_path(name)
    if path is None:
        raise PleError(f"unknown preset {echo(name)}")
    if path.suffix == ".json":
        return str(json.loads(path.read_text()).get("description", ""))
    # the first line of the program's docstring, read without running it (``ple presets`` starts at once)
    text = read_input_file(path, "program file").decode("utf-8", "replace")
    try:
        doc = ast.get_docstring(ast.parse(text, str(path))) or ""
    except SyntaxError as exc:
        raise PleError(f"{path}:{exc.lineno}: syntax error: {exc.msg}") from None
    return doc.strip().splitlines()[0] if doc.strip() else ""
