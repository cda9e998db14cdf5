"""Printer slices on disk: one 1-bit PNG per layer plus a JSON manifest, written layer by layer
(each file atomically) so memory stays one layer whatever the part's height."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..clg.grid import iter_slices
from ..errors import PleError
from .files import (
    atomic_dir,
    atomic_path,
    atomic_write_text,
    check_output_dir,
    strict_json,
)

SLICES_FORMAT = "ple-slices/1"
KIND = "ple-slices"  # the output folder's marker (ple.io.files): only such a folder is replaced


def slice_meta(lo, hi, layer: float, pixel: float) -> dict:
    """The manifest fields of a slice stack that do not depend on its layers' contents."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return {"layer": layer, "pixel": pixel, "origin": [float(lo[0]), float(lo[1]), float(lo[2])],
            "bounds": [lo.tolist(), hi.tolist()], "rows": "row 0 is the largest y"}


def write_slices(out_dir, layers: Iterable, meta: dict, progress=None) -> dict:
    """Write ``layer_00000.png`` … from (index, z, mask) items and ``manifest.json``; returns it.
    The folder appears complete or not at all (written beside it, then renamed); a slices folder
    written by PLE (its marker) is replaced, a new or empty one used, any other refused
    (``ple.io.files.check_output_dir``: nothing of the user's is overwritten)."""
    try:
        from PIL import Image  # noqa: F401 - checked before anything is written
    except ImportError:
        raise PleError("writing PNG slices needs Pillow (pip install pillow)") from None
    out = Path(out_dir)
    check_output_dir(out, KIND)
    with atomic_dir(out, KIND, "ple slice") as tmp:
        manifest = _write_layers(tmp, layers, meta, progress)
    return manifest


def _write_layers(out: Path, layers: Iterable, meta: dict, progress=None) -> dict:
    from PIL import Image

    files, zs, filled = [], [], []
    shape = None
    for k, z, mask in layers:
        name = f"layer_{k:05d}.png"
        img = Image.fromarray(np.asarray(mask, bool)).convert("1")
        with atomic_path(out / name) as tmp:
            img.save(tmp, format="PNG")
        files.append(name)
        zs.append(z)
        filled.append(int(np.count_nonzero(mask)))
        shape = mask.shape
        if progress is not None:
            progress(1)
    manifest = dict(meta, format=SLICES_FORMAT, layers=len(files), files=files, z=zs, filled_pixels=filled,
                    image_size=[int(shape[1]), int(shape[0])] if shape else [0, 0])
    atomic_write_text(out / "manifest.json", strict_json(manifest, "the slice manifest", indent=1) + "\n")
    return manifest


def write_pmc_slices(out_dir, pmc, lo, hi, layer: float, pixel: float, progress=None) -> dict:
    """Printer slices of a membership function ``pmc`` (points (n, 3) -> bool (n,)) over the box
    [lo, hi] (layer centres and pixel centres as ``clg.grid.iter_slices``); returns the manifest."""
    meta = slice_meta(lo, hi, layer, pixel)
    return write_slices(out_dir, iter_slices(pmc, lo, hi, layer, pixel), meta, progress)
