"""Stream a filter over a lattice larger than memory: slabs in, ``.npz`` chunks out.

The filtered lattice is walked slab by slab (``Lattice.iter_slabs``, boxes of node-groups in
(i, j, k) order). Each node is decided once, in its own slab; its output row is global (the
chunks' nodes concatenated in order). A beam is written with the later of its two slabs, when
both of its nodes have been decided: the row maps of earlier slabs are kept only while a beam
offset can still reach them (i-layers within max |di| of the current slab), so memory stays
bounded by one slab plus a few i-layers of row maps.

Output directory: ``manifest.json`` (format ``ple-chunks/1``) and ``chunk_NNNNNN.npz`` files
with the arrays of ``ple eval`` — node_index, center, radius (this slab's surviving nodes),
beam_index, beam_nodes (beams completed in this slab; rows index the concatenation of all
chunks' nodes). ``load_chunks`` reassembles them into one Evaluation.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from .errors import PleError
from .files import check_output_dir, make_temp_dir, remove_stale_temporaries, replace_dir, write_marker
from .filters import FilteredLattice, beams_between
from .lattice import Evaluation

FORMAT = "ple-chunks/1"
KIND = "ple-chunks"  # the output-folder marker's kind
DEFAULT_SLAB_GROUPS = 1 << 18
DISK_MARGIN = 256 << 20  # stop before the disk is full, not when it is


class Progress:
    """A one-line progress bar on a terminal (stderr); silent when not a terminal."""

    def __init__(self, total: int, label: str, stream=None, enabled: bool | None = None) -> None:
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.total, self.label, self.done = max(total, 1), label, 0
        self.t0 = time.perf_counter()
        self._last = -1.0

    def update(self, step: int, note: str = "") -> None:
        self.done += step
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        frac = min(self.done / self.total, 1.0)
        bar = "#" * int(30 * frac)
        self.stream.write(f"\r{self.label} [{bar:<30}] {100 * frac:5.1f}% {now - self.t0:6.1f}s {note}")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def stream_filter(flat: FilteredLattice, out_dir, region=None, slab_groups: int = DEFAULT_SLAB_GROUPS,
                  progress: bool | None = None) -> dict:
    """Write the surviving nodes and beams of ``region`` (default: all) as chunks in ``out_dir``.

    Returns the manifest. The directory appears complete or not at all (written beside it,
    then renamed); a chunk directory written by PLE (its ``.ple-output.json`` marker) is
    replaced, an empty one used, any other refused (``ple.files.check_output_dir``)."""
    out = Path(out_dir)
    check_output_dir(out, KIND)
    parent = out.parent if str(out.parent) else Path(".")
    if int(slab_groups) < 1:
        raise PleError(f"slab size must be at least 1 node-group, got {slab_groups}")
    lat = flat.lattice
    lat.validate()
    r = lat.region(region)
    remove_stale_temporaries(parent)
    _check_disk_bound(lat, r, parent)
    tmp = make_temp_dir(parent, out.name)
    try:
        manifest = _write_chunks(flat, r, tmp, int(slab_groups), progress)
        write_marker(tmp, KIND, "ple filter")
        replace_dir(tmp, out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return manifest


def _check_disk_bound(lat, r, parent: Path) -> None:
    """Refuse a stream whose output, if every node and beam survived, could not fit on the disk."""
    from .budget import EVAL_BEAM_BYTES, EVAL_NODE_BYTES, human, region_beams, region_nodes

    bound = region_nodes(lat, r) * EVAL_NODE_BYTES + region_beams(lat, r) * EVAL_BEAM_BYTES
    free = shutil.disk_usage(parent).free
    if bound + DISK_MARGIN > free:
        raise PleError(f"region {r} could stream up to {human(bound)} of chunks (if every node survives), more than "
                       f"the {human(free)} free in {parent}; choose a smaller --region")


def _write_chunks(flat: FilteredLattice, r, folder: Path, slab_groups: int, progress) -> dict:
    lat = flat.lattice
    reach_i = max((abs(b.di) for b in lat.beams), default=0)
    bar = Progress(r.groups, "filter", enabled=progress)
    retained: list[tuple] = []  # (slab region, global row map) of slabs a later beam may reach
    chunks, node_offset, beam_total = [], 0, 0
    for n, slab in enumerate(lat.iter_slabs(slab_groups, r)):
        nodes, rows = flat.region_rows(slab)
        rows = np.where(rows >= 0, rows + node_offset, -1)
        retained = [(s, m) for s, m in retained if s.i1 - 1 + reach_i >= slab.i0]
        parts = [beams_between(lat, slab, rows, slab, rows)]
        for s, m in retained:
            parts.append(beams_between(lat, s, m, slab, rows))
            parts.append(beams_between(lat, slab, rows, s, m))
        idx = np.concatenate([p[0] for p in parts])
        ends = np.concatenate([p[1] for p in parts])
        order = np.lexsort((idx[:, 3], idx[:, 2], idx[:, 1], idx[:, 0]))
        name = f"chunk_{n:06d}.npz"
        need = nodes.center.nbytes * 3 + idx.nbytes * 2 + DISK_MARGIN
        if shutil.disk_usage(folder).free < need:
            raise PleError(f"the disk of {folder.parent} is nearly full after {n} chunks ({node_offset:,} nodes); "
                           "nothing was written — free space or choose a smaller --region")
        with open(folder / name, "wb") as fh:
            np.savez(fh, node_index=nodes.node_index, center=nodes.center, radius=nodes.radius,
                     beam_index=idx[order], beam_nodes=ends[order])
        chunks.append({"file": name, "region": str(slab), "nodes": len(nodes.node_index), "beams": len(idx),
                       "node_offset": node_offset})
        node_offset += len(nodes.node_index)
        beam_total += len(idx)
        retained.append((slab, rows))
        bar.update(slab.groups, f"{node_offset:,} nodes {beam_total:,} beams kept")
    bar.close()
    manifest = {"format": FORMAT, "region": str(r), "counts": list(lat.counts), "nodes": node_offset,
                "beams": beam_total, "chunks": chunks}
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return manifest


def read_manifest(folder) -> dict:
    path = Path(folder) / "manifest.json"
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise PleError(f"{folder}: not a chunk directory ({exc})") from None
    if manifest.get("format") != FORMAT:
        raise PleError(f"{path}: format {manifest.get('format')!r}, expected {FORMAT}")
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
