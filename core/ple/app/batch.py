"""Batch export of parameter variants: ``ple batch`` (and the engine of the Blender batch).

A sweep gives each input either one value (``thickness=0.05``), a list
(``thickness=0.05,0.07``) or a range ``lo:hi:n`` (n evenly spaced values, ends included);
the variants are the Cartesian product. Each variant is built, meshed and written to
``DIR/<stem>__<name>-<value>….<ext>``; ``DIR/manifest.json`` records what was produced.
Finished outputs are skipped on a re-run (resume), the variants run as Dask tasks
(``ple.app.cluster``) and progress goes to stderr.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import PleError, cut, echo
from ..io.files import atomic_write_text, check_output_dir, plain_name, write_marker
from ..io.formats import format_named
from ..meshing.styles import style as style_named
from ..meshing.tessellate import resolve_style
from ..model.budget import MESH_TRIANGLE_BYTES, mesh_triangles, require
from ..program.runner import program_inputs, run_program
from ..program.runtime import Param, parse_param_value
from ..program.sources import resolve_source
from .cluster import check_scheduler, dask_client, run_tasks, showing
from .jobs import program_limits
from .pipeline import MeshRequest, write_mesh

KIND = "ple-batch"  # the output-folder marker's kind
MAX_VARIANTS = 10_000  # per batch (the plan is listed before anything is written)


@dataclass(frozen=True)
class Variant:
    """One point of a sweep: its parameter values and output file name."""

    params: dict
    filename: str


def parse_sweep(param: Param, text: str) -> list:
    """Values of one ``--param`` sweep: ``v``, ``v1,v2,…`` or ``lo:hi:n``."""
    if ":" in text and param.kind in (int, float):
        parts = text.split(":")
        if len(parts) != 3:
            raise PleError(f"--param {param.name}={text}: a range reads lo:hi:n")
        lo, hi = (parse_param_value(param, p) for p in parts[:2])
        try:
            n = int(parts[2])
        except ValueError:
            raise PleError(f"--param {param.name}={text}: the count n must be an integer") from None
        if n < 1:
            raise PleError(f"--param {param.name}={text}: the count n must be at least 1")
        if n > MAX_VARIANTS:
            raise PleError(f"--param {param.name}={text}: the count n must be at most {MAX_VARIANTS:,}")
        values = np.linspace(float(lo), float(hi), n)
        return [int(round(v)) for v in values] if param.kind is int else [float(v) for v in values]
    parts = text.split(",")
    if len(parts) > MAX_VARIANTS:
        raise PleError(f"--param {param.name}: more than {MAX_VARIANTS:,} values")
    return [parse_param_value(param, p) for p in parts]


def _value_text(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v).replace(os.sep, "_")


def plan(source: str, sweeps: list[str], fmt: str, limits: tuple | None = None) -> tuple[str, list[Variant]]:
    """The variants of a sweep over a program's inputs (the program is compiled once, contained
    under ``limits``: ``runner.program_inputs``)."""
    format_named(fmt)
    path = resolve_source(source)
    if path.suffix != ".py":
        if sweeps:
            raise PleError(f"{source}: a .json lattice file has no inputs to sweep")
        return str(path), [Variant({}, f"{path.stem}.{fmt}")]
    known = {p.name: p for p in program_inputs(str(path), *program_limits(limits))}
    axes: dict[str, list] = {}
    for s in sweeps:
        if "=" not in s:
            raise PleError(f"--param {echo(s)}: expected NAME=VALUES")
        name, text = (x.strip() for x in s.split("=", 1))
        if name not in known:
            raise PleError(f"--param {cut(name)}: unknown parameter (inputs: {', '.join(known) or 'none'})")
        axes[name] = parse_sweep(known[name], text)
    total = math.prod(len(v) for v in axes.values())
    if total > MAX_VARIANTS:
        raise PleError(f"the sweep has {total:,} variants, more than {MAX_VARIANTS:,}; split it into several batches")
    variants = []
    for combo in itertools.product(*axes.values()):
        params = dict(zip(axes, combo))
        tag = "__".join(f"{k}-{_value_text(v)}" for k, v in params.items())
        variants.append(Variant(params, f"{path.stem}{'__' + tag if tag else ''}.{fmt}"))
    return str(path), variants


def _run_variant(source: str, params: dict, style: str, levels, region, out: str, limits=None) -> dict:
    """Worker: build (contained, ``limits`` = (timeout, memory); ``ple.program.runner``), check
    the work budget, and write one variant through the one mesh pipeline (``pipeline.write_mesh``,
    as ``ple mesh``: unclean hubs united locally, the float32 grid); returns its manifest entry
    (``watertight`` read back from the file written)."""
    import trimesh
    t0 = time.perf_counter()
    timeout, memory = program_limits(limits)
    lat = run_program(source, params, timeout, memory)
    r = lat.region(region)
    lv, seg = resolve_style(style if style != "balls-beams" else "cnt", levels, None)
    tris = mesh_triangles(lat, r, style, lv, seg)
    require(tris * MESH_TRIANGLE_BYTES, f"{Path(out).name}: {tris:,.3g} triangles", memory,
            "choose a smaller --region or fewer --levels")
    count = write_mesh(MeshRequest(lat, r, style, levels=levels, max_memory=memory), Path(out))
    size, digest = file_digest(Path(out))
    closed = style_named(style).solid and bool(trimesh.load(Path(out), force="mesh").is_watertight)
    return {"file": Path(out).name, "params": params, "triangles": int(count),
            "bytes": size, "sha256": digest, "seconds": round(time.perf_counter() - t0, 3),
            "watertight": closed}


def run_batch(source: str, sweeps: list[str], out_dir, style: str = "refined", fmt: str = "stl",
              levels: int | None = None, region: str | None = None, jobs: int | None = None,
              progress=True, limits: tuple | None = None, scheduler: str | None = "local") -> dict:
    """Export every variant of a sweep; skip those already in the manifest with their file.
    ``limits``: (timeout s, memory bytes) of each variant's program and mesh
    (``ple.program.runner``). The variants run on Dask (``ple.app.cluster.dask_client``: an
    embedded cluster of ``jobs`` workers by default, ``sync`` in this process, or a scheduler
    address); a variant whose worker dies is rerun, then reported by name."""
    style_named(style)
    check_scheduler(scheduler, jobs)  # before anything is created
    path, variants = plan(source, sweeps, fmt, limits)
    out = Path(out_dir)
    manifest_path = out / "manifest.json"
    manifest = check_batch_dir(out)
    done = {e["file"] for e in manifest["outputs"] if recorded(out, e)}  # size and SHA-256 as recorded
    todo = [v for v in variants if v.filename not in done]
    manifest.update({"program": path, "style": style, "format": fmt, "region": region})
    manifest["outputs"] = [e for e in manifest["outputs"] if e["file"] in done]
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(todo) or 1))
    failures = []
    t0 = time.perf_counter()
    with contextlib.ExitStack() as stack:
        client = None
        if todo:  # the scheduler is reached before the folder is created or marked
            client = stack.enter_context(dask_client(scheduler, jobs, showing(None if progress else False)))
        make_batch_dir(out, "ple batch")
        if todo:
            tasks = [(path, v.params, style, levels, region, str(out / v.filename), limits) for v in todo]
            for v, result in run_tasks(client, _run_variant, tasks, todo, "batch", [v.filename for v in todo],
                                       None if progress else False):
                if isinstance(result, Exception):
                    error = str(result) if isinstance(result, PleError) else f"worker died: {result}"
                    failures.append({"file": v.filename, "params": v.params, "error": error})
                else:
                    manifest["outputs"].append(result)
                atomic_write_text(manifest_path, json.dumps(manifest, indent=1, allow_nan=False) + "\n")
    manifest["failures"] = failures
    atomic_write_text(manifest_path, json.dumps(manifest, indent=1, allow_nan=False) + "\n")
    return {"written": len(todo) - len(failures), "skipped": len(variants) - len(todo), "failed": failures,
            "manifest": str(manifest_path), "seconds": time.perf_counter() - t0}


def prepare_output_dir(out: Path, command: str) -> dict:
    """Check, create and mark a batch output folder (ours, new or empty; never another folder's
    files: ``ple.io.files.check_output_dir``); returns its manifest (empty when new)."""
    manifest = check_batch_dir(out)
    make_batch_dir(out, command)
    return manifest


def check_batch_dir(out: Path) -> dict:
    """The manifest of a batch output folder that is ours, new or empty (empty when new); any
    other folder is refused. Creates nothing."""
    manifest_path = out / "manifest.json"
    if not _legacy_batch_folder(manifest_path):  # written before output markers existed
        check_output_dir(out, KIND)
    return read_manifest(manifest_path)


def file_digest(path: Path, block: int = 1 << 20) -> tuple[int, str]:
    """(size, SHA-256 hex) of a file, read a block at a time."""
    h, size = hashlib.sha256(), 0
    with open(path, "rb") as fh:
        while data := fh.read(block):
            h.update(data)
            size += len(data)
    return size, h.hexdigest()


def recorded(out: Path, entry: dict) -> bool:
    """Is a manifest entry's file there with the size and SHA-256 recorded for it? (An entry
    without a hash, written before hashes were recorded, is made again.)"""
    path = out / entry["file"]
    try:
        if not path.is_file() or path.stat().st_size != entry.get("bytes"):
            return False
        return file_digest(path) == (entry["bytes"], entry.get("sha256"))
    except OSError:
        return False


def make_batch_dir(out: Path, command: str) -> None:
    """Create and mark a batch output folder checked by ``check_batch_dir``."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PleError(f"--out {out}: cannot create the folder ({exc.strerror})") from None
    write_marker(out, KIND, command)


def _legacy_batch_folder(manifest_path: Path) -> bool:
    try:
        return json.loads(manifest_path.read_text()).get("format") == "ple-batch/1"
    except (OSError, ValueError, RecursionError, AttributeError):
        return False


def read_manifest(path: Path) -> dict:
    if not path.is_file():
        return {"format": "ple-batch/1", "outputs": []}
    try:
        data = json.loads(path.read_text())
    except (ValueError, RecursionError, OSError):
        raise PleError(f"{path}: existing manifest is not valid JSON; move it away to start afresh") from None
    if not isinstance(data, dict) or not isinstance(data.get("outputs"), list):
        raise PleError(f"{path}: existing manifest has no 'outputs' list")
    for n, entry in enumerate(data["outputs"]):
        if not isinstance(entry, dict) or not isinstance(entry.get("file"), str):
            raise PleError(f"{path}: outputs[{n}] is not an entry with a 'file' name; move the manifest away "
                           "to start afresh")
        plain_name(entry["file"], f"{path}: outputs[{n}].file")
    return data
