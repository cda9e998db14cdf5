"""``ple-lattice/1`` files (SPEC §5): read and validate, write atomically. Loading never runs code."""

from __future__ import annotations

import importlib
from pathlib import Path

from ..errors import PleError
from ..filters.ir import lattice_from_ir, lattice_to_ir
from ..model.lattice import Lattice
from .files import atomic_write_text, strict_json
from .inputs import read_json


def read_body(path, placement=None, open: str = "error", name: str | None = None):  # noqa: A002
    """``ple.io.bodyfile.load_body``, imported on first use: reading meshes needs trimesh, which
    costs about a second and which a command that loads no body should not pay for at start-up
    (tests/cli/test_main.py)."""
    return importlib.import_module(f"{__package__}.bodyfile").load_body(path, placement, open, name)


def body_loader(folder):
    """The loader ``lattice_from_ir`` resolves a body filter's mesh with: its path resolves against
    ``folder`` (the JSON file's folder; absolute paths stand), and the file is read as triangles
    only, never executed. Every door that reads IR data with bodies (files, the add-on's text
    blocks and presets) resolves through it."""
    folder = Path(folder)

    def loader(mesh: str, placement, opened: str, where: str):
        return read_body(folder / mesh, placement, opened, f"{where} {mesh!r}")

    return loader


def load_ir(path) -> Lattice:
    """Load and validate a ``ple-lattice/1`` file."""
    path = Path(path)
    data = read_json(path, "lattice file")  # within limits: size, UTF-8, depth (ple.io.inputs)
    try:
        return lattice_from_ir(data, body_loader(path.parent))
    except PleError as exc:
        raise PleError(f"{path}: {exc}") from None


def save_ir(lat: Lattice, path, resolved: bool = True) -> None:
    """Write the IR atomically (no partial file on failure); body mesh paths relative to it."""
    base = Path(path).parent
    atomic_write_text(path, strict_json(lattice_to_ir(lat, resolved, base), "the IR", indent=1) + "\n")
