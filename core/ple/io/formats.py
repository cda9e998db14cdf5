"""The registry of output mesh formats: suffixes, what each file carries, and its axis convention;
read by the CLI, batch jobs, the add-on and the writers."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import PleError


@dataclass(frozen=True)
class MeshFormat:
    """An output format: ``name`` (the suffix), ``label``, ``streams`` True when written box by
    box with bounded memory, ``up`` the axis the format's consumers treat as up."""

    name: str
    label: str
    description: str
    streams: bool
    up: str


MESH_FORMATS = {f.name: f for f in (
    MeshFormat("stl", "STL", "binary STL, float32 triangles (streamed: memory bounded by a box of groups)", True, "Z"),
    MeshFormat("3mf", "3MF", "3D Manufacturing Format mesh, millimetres", False, "Z"),
    MeshFormat("ply", "PLY", "binary PLY, indexed vertices", False, "Z"),
    MeshFormat("obj", "OBJ", "Wavefront OBJ, indexed vertices", False, "Y"),
    MeshFormat("glb", "glTF binary", "glTF 2.0 binary, float32 vertices", False, "Y"),
)}
FORMAT_NAMES = tuple(MESH_FORMATS)


def mesh_format(path) -> str:
    """The output format named by ``path``'s suffix (one of FORMAT_NAMES)."""
    suffix = Path(path).suffix.lower().lstrip(".")
    return format_named(suffix, f"{path}: unknown mesh format {suffix!r}")


def format_named(name: str, what: str | None = None) -> str:
    """``name`` if it is a mesh format, else a user error listing them."""
    if name not in MESH_FORMATS:
        raise PleError(f"{what or f'--format {name!r}'} (expected one of .{', .'.join(FORMAT_NAMES)})")
    return name
