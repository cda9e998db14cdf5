"""The registry of output mesh formats: suffixes, what each file carries, its axis convention and
unit; read by the CLI, batch jobs, the add-on and the writers.

Conventions: PLE's coordinates are Z-up, in the unit the user states (``unit``, default mm).
A Y-up format (glTF, OBJ) gets them turned by ``Y_UP`` ((x, y, z) -> (x, z, -y)); a format
with a unit fixed by its specification (glTF: metres) gets them scaled to it; the others carry
the unit as written (3MF's ``unit`` attribute, a comment in STL's header, PLY and OBJ)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import PleError, echo

# unit: (3MF name, metres per unit)
UNITS = {"um": ("micron", 1e-6), "mm": ("millimeter", 1e-3), "cm": ("centimeter", 1e-2),
         "in": ("inch", 0.0254), "ft": ("foot", 0.3048), "m": ("meter", 1.0)}
DEFAULT_UNIT = "mm"
Y_UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # (x, y, z) -> (x, z, -y): Z-up data in a Y-up file


@dataclass(frozen=True)
class MeshFormat:
    """An output format: ``name`` (the suffix), ``label``, ``streams`` True when written box by
    box with bounded memory, ``up`` the axis the format's consumers treat as up, ``unit`` the
    unit fixed by the format (None: the user's unit, stated in the file)."""

    name: str
    label: str
    description: str
    streams: bool
    up: str
    unit: str | None = None


MESH_FORMATS = {f.name: f for f in (
    MeshFormat("stl", "STL", "binary STL, float32 triangles (streamed: memory bounded by a box of groups)", True, "Z"),
    MeshFormat("3mf", "3MF", "3D Manufacturing Format mesh, unit in the model (default millimetres)", False, "Z"),
    MeshFormat("ply", "PLY", "binary PLY, indexed float32 vertices", False, "Z"),
    MeshFormat("obj", "OBJ", "Wavefront OBJ, indexed vertices, Y up", False, "Y"),
    MeshFormat("glb", "glTF binary", "glTF 2.0 binary, float32 vertices, Y up, metres", False, "Y", "m"),
)}
FORMAT_NAMES = tuple(MESH_FORMATS)


def mesh_format(path) -> str:
    """The output format named by ``path``'s suffix (one of FORMAT_NAMES)."""
    suffix = Path(path).suffix.lower().lstrip(".")
    return format_named(suffix, f"{path}: unknown mesh format {echo(suffix)}")


def format_named(name: str, what: str | None = None) -> str:
    """``name`` if it is a mesh format, else a user error listing them."""
    if name not in MESH_FORMATS:
        raise PleError(f"{what or f'--format {echo(name)}'} (expected one of .{', .'.join(FORMAT_NAMES)})")
    return name


def unit_name(unit: str) -> str:
    """The 3MF name of a unit ("mm" -> "millimeter"); a user error for an unknown unit."""
    if unit not in UNITS:
        raise PleError(f"--unit {echo(unit)}: expected one of {', '.join(UNITS)}")
    return UNITS[unit][0]


def to_file_axes(vertices: np.ndarray, fmt: str, unit: str = DEFAULT_UNIT) -> np.ndarray:
    """Z-up ``vertices`` in ``unit`` as format ``fmt`` stores them: turned Y-up for a Y-up
    format, scaled to the format's own unit if it has one."""
    f = MESH_FORMATS[format_named(fmt)]
    v = np.asarray(vertices, float).reshape(-1, 3)
    if f.up == "Y":
        v = v @ Y_UP.T
    if f.unit is not None:
        unit_name(unit)
        v = v * (UNITS[unit][1] / UNITS[f.unit][1])
    return v


def from_file_axes(vertices: np.ndarray, fmt: str, unit: str = DEFAULT_UNIT) -> np.ndarray:
    """The inverse of ``to_file_axes``: vertices read from a file of format ``fmt`` back in
    PLE's Z-up axes and in ``unit``."""
    f = MESH_FORMATS[format_named(fmt)]
    v = np.asarray(vertices, float).reshape(-1, 3)
    if f.unit is not None:
        unit_name(unit)
        v = v * (UNITS[f.unit][1] / UNITS[unit][1])
    if f.up == "Y":
        v = v @ Y_UP  # the inverse rotation
    return v
