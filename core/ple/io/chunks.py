"""Stream a filter over a lattice larger than memory: slabs in, ``.npz`` chunks out.

The filtered lattice is walked slab by slab (``Lattice.iter_evaluation``, boxes of node-groups
in (i, j, k) order). Each node is decided once, in its own slab; its output row is global (the
chunks' nodes concatenated in order). A beam is written with the later of its two slabs, when
both of its nodes have been decided, so memory stays bounded by one slab plus a few i-layers
of row maps.

Output directory: ``manifest.json`` (format ``ple-chunks/1``) and ``chunk_NNNNNN.npz`` files
with the arrays of ``ple eval`` — node_index, center, radius (this slab's surviving nodes),
beam_index, beam_nodes (beams completed in this slab; rows index the concatenation of all
chunks' nodes). ``load_chunks`` reassembles them into one Evaluation.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from ..errors import PleError, echo
from ..model.budget import EVAL_BEAM_BYTES, EVAL_NODE_BYTES, human, region_beams, region_nodes
from ..model.lattice import Evaluation, Lattice
from .files import atomic_dir, check_output_dir, remove_stale_temporaries, strict_json

FORMAT = "ple-chunks/1"
KIND = "ple-chunks"  # the output-folder marker's kind
DEFAULT_SLAB_GROUPS = 1 << 18
DISK_MARGIN = 256 << 20  # stop before the disk is full, not when it is


def stream_filter(lat: Lattice, out_dir, region=None, slab_groups: int = DEFAULT_SLAB_GROUPS,
                  progress=None) -> dict:
    """Write the surviving nodes and beams of ``region`` (default: all) as chunks in ``out_dir``.

    ``progress``: an object with ``update(groups, note)`` and ``close()`` (e.g.
    ``ple.app.progress.Progress``), or None. Returns the manifest. The directory appears
    complete or not at all (written beside it, then renamed); a chunk directory written by PLE
    (its ``.ple-output.json`` marker) is replaced, an empty one used, any other refused
    (``ple.io.files.check_output_dir``)."""
    out = Path(out_dir)
    check_output_dir(out, KIND)
    parent = out.parent if str(out.parent) else Path(".")
    if int(slab_groups) < 1:
        raise PleError(f"slab size must be at least 1 node-group, got {slab_groups}")
    lat.validate()
    r = lat.region(region)
    remove_stale_temporaries(parent)
    _check_disk_bound(lat, r, parent)
    with atomic_dir(out, KIND, "ple filter") as tmp:
        manifest = _write_chunks(lat, r, tmp, int(slab_groups), progress)
    return manifest


def _check_disk_bound(lat: Lattice, r, parent: Path) -> None:
    """Refuse a stream whose output, if every node and beam survived, could not fit on the disk."""
    bound = region_nodes(lat, r) * EVAL_NODE_BYTES + region_beams(lat, r) * EVAL_BEAM_BYTES
    free = shutil.disk_usage(parent).free
    if bound + DISK_MARGIN > free:
        raise PleError(f"region {r} could stream up to {human(bound)} of chunks (if every node survives); with "
                       f"{human(DISK_MARGIN)} kept free, more than the {human(free)} free in {parent}; "
                       "choose a smaller --region or free some space")


def _write_chunks(lat: Lattice, r, folder: Path, slab_groups: int, progress) -> dict:
    chunks, node_offset, beam_total = [], 0, 0
    for n, (slab, ev) in enumerate(lat.iter_evaluation(r, slab_groups)):
        name = f"chunk_{n:06d}.npz"
        need = ev.center.nbytes * 3 + ev.beam_index.nbytes * 2 + DISK_MARGIN
        if shutil.disk_usage(folder).free < need:
            raise PleError(f"the disk of {folder.parent} is nearly full after {n} chunks ({node_offset:,} nodes); "
                           "nothing was written — free space or choose a smaller --region")
        with open(folder / name, "wb") as fh:
            np.savez(fh, **ev.arrays())
        chunks.append({"file": name, "region": str(slab), "nodes": len(ev.node_index), "beams": len(ev.beam_index),
                       "node_offset": node_offset})
        node_offset += len(ev.node_index)
        beam_total += len(ev.beam_index)
        if progress:
            progress.update(slab.groups, f"{node_offset:,} nodes {beam_total:,} beams kept")
    if progress:
        progress.close()
    manifest = {"format": FORMAT, "region": str(r), "counts": list(lat.counts), "nodes": node_offset,
                "beams": beam_total, "chunks": chunks}
    (folder / "manifest.json").write_text(strict_json(manifest, "the chunk manifest", indent=1))
    return manifest


def read_manifest(folder) -> dict:
    path = Path(folder) / "manifest.json"
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise PleError(f"{folder}: not a chunk directory ({exc})") from None
    if manifest.get("format") != FORMAT:
        raise PleError(f"{path}: format {echo(manifest.get('format'))}, expected {FORMAT}")
    return manifest


def iter_chunks(folder):
    """Yield (chunk entry, arrays dict) in order, one chunk in memory at a time."""
    folder = Path(folder)
    for entry in read_manifest(folder)["chunks"]:
        with np.load(folder / entry["file"], allow_pickle=False) as z:
            yield entry, {k: z[k] for k in z.files}


def load_chunks(folder) -> Evaluation:
    """All chunks as one Evaluation, beams sorted by (i, j, k, pattern) as ``ple eval``."""
    parts = [a for _, a in iter_chunks(folder)]
    cat = {k: np.concatenate([p[k] for p in parts]) if parts else None for k in
           ("node_index", "center", "radius", "beam_index", "beam_nodes")}
    if not parts:
        return Evaluation(np.zeros((0, 4), np.int64), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 4), np.int64),
                          np.zeros((0, 2), np.int64))
    idx = cat["beam_index"]
    order = np.lexsort((idx[:, 3], idx[:, 2], idx[:, 1], idx[:, 0]))
    return Evaluation(cat["node_index"], cat["center"], cat["radius"], idx[order], cat["beam_nodes"][order])
