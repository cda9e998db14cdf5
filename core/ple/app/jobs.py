"""Partitioned jobs: a job is a list of independent parts with deterministic names, each written
by a worker, atomically, to an output location (a local folder or any fsspec URL the workers
share), with a manifest recording each part's parameters, size, hash and time.

Kinds: a sweep (one part per program variant, ``ple batch``), a big mesh (one part per box of
node-groups, binary STL; the boxes' boundary hubs are handled as by the streamed tessellation, so
the parts close up), a filtered lattice (one part per slab of node-groups, ``.npz``; ``ple lil``,
``ple filter``). Parts are computed by ``ple.app.cluster.run_parts`` (Dask, an embedded local
cluster by default, or a real one). Re-running a job skips every part already written and
valid (its hash matches the manifest): a crash or a Ctrl-C loses no finished work.
"""

from __future__ import annotations

import hashlib
import io
import json
import posixpath
import time
import uuid
from dataclasses import dataclass, field

import fsspec
import numpy as np

from ..errors import PleError
from ..filters.ir import filter_from_dict
from ..io.export import mesh_bytes, stl_header, stl_records
from ..io.files import atomic_path
from ..io.formats import format_named
from ..meshing.styles import style as style_named
from ..meshing.tessellate import output_grid, tessellate, tessellation_box
from ..meshing.weld import snap_triangles
from ..model.lattice import Evaluation, Region
from ..program.runner import run_program
from ..program.sources import load_lattice, resolve_source

FORMAT = "ple-job/1"
MANIFEST = "manifest.json"
STL_HEADER = stl_header(what="partitioned mesh")


@dataclass(frozen=True)
class Part:
    """One independent piece of a job: a deterministic ``name`` (its file) and its parameters."""

    name: str
    params: dict


@dataclass
class Job:
    """What to compute: ``kind`` (sweep, mesh, filter), the parts and the job-wide settings that
    every part needs (program source and inputs, style, …)."""

    kind: str
    settings: dict
    parts: list[Part] = field(default_factory=list)


# ----- locations ------------------------------------------------------------------------------------
def location(url: str, create: bool = True):
    """(filesystem, root path) of a local folder or an fsspec URL; created if missing (else, with
    ``create`` False, an error: reading a job never creates anything)."""
    try:
        fs, root = fsspec.core.url_to_fs(str(url))
    except (ValueError, ImportError) as exc:
        raise PleError(f"--out {url}: not a usable location ({exc})") from None
    if fs.isfile(root):
        raise PleError(f"--out {url}: is a file, not a folder")
    if not create:
        if not fs.isdir(root):
            raise PleError(f"{url}: no such folder of job parts")
        return fs, root
    try:
        fs.makedirs(root, exist_ok=True)
    except OSError as exc:
        raise PleError(f"--out {url}: cannot create it ({exc.strerror or exc})") from None
    return fs, root


def write_atomic(fs, path: str, data: bytes) -> None:
    """Write ``data`` to ``path``: a temporary sibling, then a rename (one put on object stores),
    so a reader never sees half a part, also when the worker is killed."""
    tmp = f"{path}.tmp-{uuid.uuid4().hex}"
    try:
        with fs.open(tmp, "wb") as fh:
            fh.write(data)
        fs.mv(tmp, path)
    finally:
        if fs.exists(tmp):
            fs.rm(tmp)


def read_manifest(fs, root: str) -> dict:
    path = posixpath.join(root, MANIFEST)
    if not fs.exists(path):
        return {}
    try:
        data = json.loads(fs.cat_file(path))
    except (ValueError, RecursionError):  # RecursionError: JSON nested beyond Python's stack
        raise PleError(f"{path}: not a valid job manifest (JSON); move it away to start afresh") from None
    if (not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(data.get("parts"), dict)
            or not isinstance(data.get("order", []), list)):
        raise PleError(f"{path}: not a {FORMAT} manifest; choose an empty --out")
    return data


def valid_parts(fs, root: str, manifest: dict) -> set[str]:
    """Names of the parts present with the size and hash the manifest recorded for them."""
    ok = set()
    for name, entry in manifest.get("parts", {}).items():
        path = posixpath.join(root, name)
        try:
            if fs.size(path) == entry["bytes"] and hashlib.sha256(fs.cat_file(path)).hexdigest() == entry["sha256"]:
                ok.add(name)
        except (OSError, KeyError, TypeError):
            continue
    return ok


def _params(params) -> list | dict:
    """Program inputs as given (``NAME=VALUE`` texts or a dict), JSON-able for the manifest."""
    return list(params) if isinstance(params, (list, tuple)) else dict(params or {})


# ----- building jobs --------------------------------------------------------------------------------
def sweep_job(source: str, variants: list, style: str, fmt: str, levels=None, region=None) -> Job:
    """One part per variant (``ple.app.batch.plan``): build, mesh, write in ``fmt``."""
    style_named(style)
    format_named(fmt)
    settings = {"source": str(resolve_source(source)), "style": style, "format": fmt, "levels": levels,
                "region": region}
    return Job("sweep", settings, [Part(v.filename, dict(v.params)) for v in variants])


MAX_PARTS = 100_000  # parts of one job: its manifest and task list are held whole


def _check_parts(r, box_groups: int, flag: str) -> None:
    parts = -(-r.groups // max(1, int(box_groups)))
    if parts > MAX_PARTS:
        raise PleError(f"region {r}: {r.groups:,} node-groups make at least {parts:,} parts of {box_groups:,} "
                       f"(limit {MAX_PARTS:,}); choose a larger {flag} or a smaller --region")


def mesh_job(source: str, params: dict, style: str = "refined", levels=None, region=None,
             box_groups: int = 1 << 14) -> Job:
    """One binary-STL part per box of node-groups of ``region`` (``Lattice.iter_slabs`` order)."""
    style_named(style)
    if style == "balls-beams":
        raise PleError("a partitioned mesh needs a closed style (refined, cnt or chocc)")
    lat = run_program(source, params)  # contained (ple.program.runner), as every command's program
    r = lat.region(region)
    _check_parts(r, box_groups, "--box-groups")
    settings = {"source": str(resolve_source(source)), "params": _params(params), "style": style, "levels": levels,
                "region": str(r)}
    parts = [Part(f"part_{n:06d}.stl", {"box": str(box)}) for n, box in enumerate(lat.iter_slabs(box_groups, r))]
    return Job("mesh", settings, parts)


def filter_job(lat_source: str, params: dict, region=None, slab_groups: int = 1 << 18, filter_spec=None) -> Job:
    """One ``.npz`` part per slab of a (filtered) lattice: its kept nodes and the beams whose
    from-group lies in the slab (both ends kept), ends given as node indices."""
    lat = run_program(lat_source, params)
    r = lat.region(region)
    _check_parts(r, slab_groups, "slab size")
    settings = {"source": str(resolve_source(lat_source)), "params": _params(params), "region": str(r),
                "filter": filter_spec}
    parts = [Part(f"part_{n:06d}.npz", {"box": str(box)}) for n, box in enumerate(lat.iter_slabs(slab_groups, r))]
    return Job("filter", settings, parts)


# ----- computing one part (runs on a worker) ----------------------------------------------------------
def compute_part(kind: str, settings: dict, part: Part, url: str) -> dict:
    """Compute ``part`` and write it under ``url``; returns its manifest entry. Runs in a worker:
    everything it needs is in its arguments (no state shared with the client)."""
    t0 = time.perf_counter()
    fs, root = fsspec.core.url_to_fs(url)
    data, extra = _PARTS[kind](settings, part)
    write_atomic(fs, posixpath.join(root, part.name), data)
    return {"params": part.params, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(),
            "seconds": round(time.perf_counter() - t0, 3), **extra}


def _sweep_part(settings: dict, part: Part) -> tuple[bytes, dict]:
    lat = load_lattice(settings["source"], part.params)
    mesh = tessellate(lat, settings["region"], settings["style"], settings["levels"])
    extra = {"triangles": int(len(mesh.faces))}
    if settings["style"] != "balls-beams":
        extra["watertight"] = bool(mesh.is_watertight)
    return mesh_bytes(mesh, settings["format"]), extra


def _mesh_part(settings: dict, part: Part) -> tuple[bytes, dict]:
    lat = load_lattice(settings["source"], settings["params"])
    verts, faces = tessellation_box(lat, settings["region"], part.params["box"], settings["style"],
                                    settings["levels"])
    # the whole region's float32 grid, as the streamed STL (``write_mesh``): the parts close up
    rec = stl_records(snap_triangles(verts[faces], output_grid(lat, settings["region"])))
    return STL_HEADER + np.uint32(len(rec)).tobytes() + rec.tobytes(), {"triangles": int(len(rec))}


def _filter_part(settings: dict, part: Part) -> tuple[bytes, dict]:
    lat = load_lattice(settings["source"], settings["params"])
    if settings.get("filter") is not None:  # the command's filter (with the program's own one)
        lat = lat.unfiltered().with_filter(filter_from_dict(settings["filter"]))
    box = lat.region(part.params["box"])
    nodes, rows = lat.region_rows(box)
    beam_index, ends = owned_beams(lat, box, rows, lat.region(settings["region"]))
    buf = io.BytesIO()
    np.savez(buf, node_index=nodes.node_index, center=nodes.center, radius=nodes.radius, beam_index=beam_index,
             beam_ends=ends)
    return buf.getvalue(), {"nodes": int(len(nodes.node_index)), "beams": int(len(beam_index))}


def owned_beams(lat, box: Region, rows: np.ndarray, region: Region):
    """Beams whose from-group lies in ``box`` with both ends kept and in ``region``: beam_index
    (M, 4) and the node indices of both ends (M, 2, 4). The far end's filter decision is asked
    again here, so that every part is computed alone."""
    out_idx, out_ends = [], []
    lo, hi = np.array([region.i0, region.j0, region.k0]), np.array([region.i1, region.j1, region.k1])
    for p, b in enumerate(lat.beams):
        src = box.node_index(len(lat.nodes))
        src = src[(src[:, 3] == b.n1) & (rows.reshape(-1) >= 0)]
        dst = np.concatenate([src[:, :3] + b.offset, np.full((len(src), 1), b.n2)], axis=1)
        ok = np.all((dst[:, :3] >= lo) & (dst[:, :3] < hi), axis=1)
        ok[ok] = lat.keeps(dst[ok])
        out_idx.append(np.concatenate([src[ok, :3], np.full((int(ok.sum()), 1), p)], axis=1))
        out_ends.append(np.stack([src[ok], dst[ok]], axis=1))
    if not out_idx:
        return np.zeros((0, 4), np.int64), np.zeros((0, 2, 4), np.int64)
    idx, ends = np.concatenate(out_idx).astype(np.int64), np.concatenate(out_ends).astype(np.int64)
    order = np.lexsort((idx[:, 3], idx[:, 2], idx[:, 1], idx[:, 0]))
    return idx[order], ends[order]


_PARTS = {"sweep": _sweep_part, "mesh": _mesh_part, "filter": _filter_part}


# ----- assembling ---------------------------------------------------------------------------------------
def assemble_stl(url: str, out, chunk: int = 1 << 22) -> int:
    """One binary STL of a partitioned mesh: the parts' triangle records concatenated, streamed
    (never all parts in memory). Returns the triangle count."""
    fs, root = location(url, create=False)
    manifest = read_manifest(fs, root)
    if manifest.get("kind") != "mesh":
        raise PleError(f"{url}: not a partitioned mesh (kind {manifest.get('kind')!r})")
    order = manifest.get("order") or []
    if not order:
        raise PleError(f"{url}: the job manifest lists no parts (its \"order\"); re-run the job")
    missing = [p for p in order if p not in valid_parts(fs, root, manifest)]
    if missing:
        raise PleError(f"{url}: {len(missing)} part(s) missing or damaged (e.g. {missing[0]}); re-run the job")
    total = sum(manifest["parts"][p]["triangles"] for p in order)
    if total >= 2**32:
        raise PleError(f"{total:,} triangles do not fit one binary STL")
    with atomic_path(out) as tmp, open(tmp, "wb") as dst:
        dst.write(STL_HEADER + np.uint32(total).tobytes())
        for name in manifest["order"]:
            with fs.open(posixpath.join(root, name), "rb") as src:
                src.seek(84)
                while block := src.read(chunk):
                    dst.write(block)
    return total


def load_filter_parts(url: str):
    """The Evaluation of a partitioned filter job (beam ends resolved to rows)."""
    fs, root = location(url, create=False)
    manifest = read_manifest(fs, root)
    if manifest.get("kind") != "filter":
        raise PleError(f"{url}: not a partitioned filter job")
    arrays = {k: [] for k in ("node_index", "center", "radius", "beam_index", "beam_ends")}
    for name in manifest["order"]:
        with fs.open(posixpath.join(root, name), "rb") as fh, np.load(io.BytesIO(fh.read())) as z:
            for k in arrays:
                arrays[k].append(z[k])
    cat = {k: np.concatenate(v) if v else None for k, v in arrays.items()}
    nodes = cat["node_index"]
    key = {tuple(x): n for n, x in enumerate(nodes.tolist())}
    ends = np.array([[key[tuple(a)], key[tuple(b)]] for a, b in cat["beam_ends"].tolist()], np.int64).reshape(-1, 2)
    order = np.lexsort((cat["beam_index"][:, 3], cat["beam_index"][:, 2], cat["beam_index"][:, 1],
                        cat["beam_index"][:, 0]))
    return Evaluation(nodes, cat["center"], cat["radius"], cat["beam_index"][order], ends[order])
