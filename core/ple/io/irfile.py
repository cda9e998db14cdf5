"""``ple-lattice/1`` files (SPEC §5): read and validate, write atomically. Loading never runs code."""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import PleError
from ..filters.ir import lattice_from_ir, lattice_to_ir
from ..model.lattice import Lattice
from .files import atomic_write_text
from .inputs import read_json


def load_ir(path) -> Lattice:
    """Load and validate a ``ple-lattice/1`` file."""
    path = Path(path)
    data = read_json(path, "lattice file")  # within limits: size, UTF-8, depth (ple.io.inputs)
    try:
        return lattice_from_ir(data)
    except PleError as exc:
        raise PleError(f"{path}: {exc}") from None


def save_ir(lat: Lattice, path, resolved: bool = True) -> None:
    """Write the IR atomically (no partial file on failure)."""
    atomic_write_text(path, json.dumps(lattice_to_ir(lat, resolved), indent=1) + "\n")
