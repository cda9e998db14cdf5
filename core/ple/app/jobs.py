"""Partitioned jobs: a job is a list of independent parts with deterministic names, each written
by a worker, atomically, to an output location (a local folder or any fsspec URL the workers
share), with a manifest recording each part's parameters, size, hash and time.

Kinds: a sweep (one part per program variant, ``ple batch``), a big mesh (one part per box of
node-groups, binary STL; the boxes' boundary hubs are handled as by the streamed tessellation, so
the parts close up), a filtered lattice (one part per slab of node-groups, ``.npz``; ``ple lil``,
``ple filter``), kept counts of a filtered lattice (one small JSON part per slab: the 10⁹-beam
job), printer slices (one part per range of layers, packed bits; ``ple slice``). Parts are
computed by ``ple.app.cluster.run_job`` (Dask, an embedded local cluster by default, or a real
one). Re-running a job skips every part already written and valid (its hash matches the
manifest): a crash or a Ctrl-C loses no finished work.

Every run of a job's program, where the job is planned and on each worker, is contained
(``ple.program.runner.run_program``: a child process whose whole tree ends with the run) under
the command's limits, which travel with the job (``Job.limits``). A worker builds a job's
lattice once and keeps it for the job's next parts (``job_lattice``): a part costs its own work,
not the program's run, the filter's set-up or the query plans.
"""

from __future__ import annotations

import hashlib
import io
import json
import posixpath
import time
import uuid
import zipfile
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import fsspec
import numpy as np

from ..clg.grid import iter_slices, layer_grid
from ..errors import PleError, echo
from ..filters.ir import filter_from_dict
from ..io.export import mesh_bytes, stl_chunk, stl_header
from ..io.files import TMP_TAG, atomic_path, plain_name
from ..io.formats import format_named
from ..io.slices import slice_meta, write_slices
from ..meshing.styles import style as style_named
from ..model.budget import default_max_memory
from ..model.lattice import Evaluation, Lattice, Region
from ..program.runner import DEFAULT_TIMEOUT, check_timeout, run_program
from ..program.sources import resolve_source
from ..queries.biq import pmc
from . import pipeline

FORMAT = "ple-job/1"
MANIFEST = "manifest.json"
STL_HEADER = stl_header(what="partitioned mesh")
CACHE_SIZE = 4  # lattices a worker keeps between the parts of its jobs


@dataclass(frozen=True)
class Part:
    """One independent piece of a job: a deterministic ``name`` (its file) and its parameters."""

    name: str
    params: dict


Limits = tuple[float | None, int]  # (timeout s, None: none; memory bytes) of each run of a program


def program_limits(limits: tuple | None = None) -> Limits:
    """The limits of a job's program runs, ``(timeout, memory)`` as given, checked; a missing
    one is the command line's default (``runner.DEFAULT_TIMEOUT``, ``budget.default_max_memory``)."""
    timeout, memory = limits or (DEFAULT_TIMEOUT, None)
    return check_timeout(timeout), int(memory or default_max_memory())


@dataclass
class Job:
    """What to compute: ``kind`` (sweep, mesh, filter), the parts and the job-wide settings that
    every part needs (program source and inputs, style, …). ``limits`` bound each run of the
    program (``program_limits``), on every worker; they are not settings: a job resumed under
    other limits makes the same parts."""

    kind: str
    settings: dict
    parts: list[Part] = field(default_factory=list)
    limits: Limits = field(default_factory=program_limits)


# ----- locations ------------------------------------------------------------------------------------
def location(url: str, create: bool | None = True):
    """(filesystem, root path) of a local folder or an fsspec URL; created if missing (else, with
    ``create`` False, an error: reading a job never creates anything; with ``create`` None, left
    as it is: a job reaches its scheduler before it creates anything)."""
    try:
        fs, root = fsspec.core.url_to_fs(str(url))
    except (ValueError, ImportError) as exc:
        raise PleError(f"--out {url}: not a usable location ({exc})") from None
    if fs.isfile(root):
        raise PleError(f"--out {url}: is a file, not a folder")
    if create is None:
        return fs, root
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
    for name in [*data["parts"], *data.get("order", [])]:  # part names stay inside the job's folder
        plain_name(name, f"{path}: part")
    for name, entry in data["parts"].items():
        if not isinstance(entry, dict):
            raise PleError(f"{path}: parts.{name} is not an entry (bytes, sha256); move the manifest away "
                           "to start afresh")
    return data


def check_job_folder(fs, root: str, url: str) -> None:
    """A job writes into a folder that is new, empty or holds a job manifest, never into another
    folder of the user's (its files could share a part's name)."""
    if not fs.isdir(root) or fs.exists(posixpath.join(root, MANIFEST)):
        return
    try:
        names = [posixpath.basename(str(p).rstrip("/")) for p in fs.ls(root, detail=False)]
    except OSError as exc:
        raise PleError(f"--parts {url}: cannot read the folder ({exc.strerror or exc})") from None
    names = [n for n in names if TMP_TAG not in n and ".tmp-" not in n]
    if names:
        raise PleError(f"--parts {url}: folder exists, is not empty and holds no job manifest ({MANIFEST}); "
                       "not touching it — give a new or empty folder")


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
def sweep_job(source: str, variants: list, style: str, fmt: str, levels=None, region=None,
              limits: tuple | None = None) -> Job:
    """One part per variant (``ple.app.batch.plan``): build (contained, under ``limits``), mesh,
    write in ``fmt``."""
    style_named(style)
    format_named(fmt)
    settings = {"source": str(resolve_source(source)), "style": style, "format": fmt, "levels": levels,
                "region": region}
    return Job("sweep", settings, [Part(v.filename, dict(v.params)) for v in variants], program_limits(limits))


MAX_PARTS = 100_000  # parts of one job: its manifest and task list are held whole


def _check_parts(r, box_groups: int, flag: str) -> None:
    parts = -(-r.groups // max(1, int(box_groups)))
    if parts > MAX_PARTS:
        raise PleError(f"region {r}: {r.groups:,} node-groups make at least {parts:,} parts of {box_groups:,} "
                       f"(limit {MAX_PARTS:,}); choose a larger {flag} or a smaller --region")


def mesh_job(source: str, params: dict, style: str = "refined", levels=None, region=None,
             box_groups: int = 1 << 14, limits: tuple | None = None) -> Job:
    """One binary-STL part per box of node-groups of ``region`` (``Lattice.iter_slabs`` order).
    The region's float32 snap grid is computed here, once, and travels with the job. The program
    runs contained under ``limits`` (``program_limits``), here and on the workers.

    Regions up to ``MAX_CHECK_GROUPS`` groups are checked for unclean hubs first, as the
    streamed STL is (``checked_stream``); an unclean region is one part, meshed with its
    manifold3d unions exactly as ``ple mesh`` without parts (``settings["unclean"]`` says so):
    the unions join neighbourhoods across any box boundary, so they are not split. A lattice whose
    groups a map places (Möbius, TMI) is one part too: it is meshed per hub, not in boxes of groups."""
    style_named(style)
    if style == "balls-beams":
        raise PleError("a partitioned mesh needs a closed style (refined, cnt or chocc)")
    limits = program_limits(limits)
    lat = run_program(source, params, *limits)  # contained (ple.program.runner), as every command's program
    r = lat.region(region)
    _check_parts(r, box_groups, "--box-groups")
    p = pipeline.plan(pipeline.MeshRequest(lat, r, style, levels))  # the one mesh pipeline, as ple mesh
    settings = {"source": str(resolve_source(source)), "params": _params(params), "style": style, "levels": levels,
                "region": str(r), "grid": p.grid, "unclean": None}
    report = pipeline.check(p)
    if report is not None and len(report.nodes):
        settings["unclean"] = report.line()
        return Job("mesh", settings, [Part("part_000000.stl", {"box": str(r), "unions": True})], limits)
    if lat.group_map is not None:  # every hub its own template (``Lattice.per_hub``): no boxes of similar groups
        return Job("mesh", settings, [Part("part_000000.stl", {"box": str(r), "whole": True})], limits)
    parts = [Part(f"part_{n:06d}.stl", {"box": str(box)}) for n, box in enumerate(lat.iter_slabs(box_groups, r))]
    return Job("mesh", settings, parts, limits)


def filter_job(lat_source: str, params: dict, region=None, slab_groups: int = 1 << 18, filter_spec=None,
               limits: tuple | None = None) -> Job:
    """One ``.npz`` part per slab of a (filtered) lattice: its kept nodes and the beams whose
    from-group lies in the slab (both ends kept), ends given as node indices. The program runs
    contained under ``limits``, here and on the workers."""
    limits = program_limits(limits)
    lat = run_program(lat_source, params, *limits)
    r = lat.region(region)
    _check_parts(r, slab_groups, "slab size")
    settings = {"source": str(resolve_source(lat_source)), "params": _params(params), "region": str(r),
                "filter": filter_spec}
    parts = [Part(f"part_{n:06d}.npz", {"box": str(box)}) for n, box in enumerate(lat.iter_slabs(slab_groups, r))]
    return Job("filter", settings, parts, limits)


def count_job(lat_source: str, params, region=None, slab_groups: int = 1 << 19, filter_spec=None,
              limits: tuple | None = None) -> Job:
    """One small JSON part per slab: the slab's kept nodes and the kept beams whose from-group
    lies in it (``kept_counts``). Nothing but numbers is written, so a 10⁹-beam lattice costs its
    filter's work and a few bytes per slab. The program runs contained under ``limits``, here and
    on the workers."""
    limits = program_limits(limits)
    lat = run_program(lat_source, params, *limits)
    r = lat.region(region)
    settings = {"source": str(resolve_source(lat_source)), "params": _params(params), "region": str(r),
                "filter": filter_spec}
    parts = [Part(f"part_{n:06d}.json", {"box": str(box)}) for n, box in enumerate(lat.iter_slabs(slab_groups, r))]
    return Job("count", settings, parts, limits)


def slice_job(source: str, params, layer: float, pixel: float, bounds=None, layers_per_part: int = 32,
              filter_spec=None, limits: tuple | None = None) -> Job:
    """Printer slices (``ple slice``) as one part per range of ``layers_per_part`` layers; the
    box (default: the lattice's bounds, its program run here, contained under ``limits``) is
    computed here, once, and travels with the job; the workers run the program under ``limits``."""
    if int(layers_per_part) < 1:
        raise PleError(f"--layers-per-part must be at least 1, got {layers_per_part}")
    limits = program_limits(limits)
    if bounds is None:
        bounds = _with_filter(run_program(source, params, *limits), filter_spec).bounds()
    lo, hi = bounds
    zs, _, _ = layer_grid(np.asarray(lo, float), np.asarray(hi, float), layer, pixel)
    settings = {"source": str(resolve_source(source)), "params": _params(params), "filter": filter_spec,
                "lo": np.asarray(lo, float).tolist(), "hi": np.asarray(hi, float).tolist(), "layer": float(layer),
                "pixel": float(pixel)}
    step = int(layers_per_part)
    parts = [Part(f"part_{n:06d}.npz", {"layers": [k, min(k + step, len(zs))]})
             for n, k in enumerate(range(0, len(zs), step))]
    return Job("slice", settings, parts, limits)


# ----- the worker's lattice ----------------------------------------------------------------------------
_BUILT: OrderedDict = OrderedDict()


def _with_filter(lat: Lattice, spec) -> Lattice:
    """``lat`` with the command's filter (given as data), which already holds the program's own."""
    return lat if spec is None else lat.unfiltered().with_filter(filter_from_dict(spec))


def job_lattice(settings: dict, limits: tuple | None = None) -> Lattice:
    """The lattice of a job's settings, its program run contained under ``limits``
    (``program_limits``) once per worker process, and kept for the job's next parts (with the
    filter's index and the query plans it grows); keyed by the program's text, the inputs, the
    filter and the limits, so an edited program, or one given more time, is built again. A run
    that failed is kept as its error: the job's other parts on this worker fail at once with it,
    rather than each waiting out the time limit again."""
    limits = program_limits(limits)
    text = hashlib.sha256(Path(settings["source"]).read_bytes()).hexdigest()
    key = (text, json.dumps(settings.get("params"), sort_keys=True), json.dumps(settings.get("filter"), sort_keys=True),
           limits)
    if key in _BUILT:
        _BUILT.move_to_end(key)
    else:
        try:
            _BUILT[key] = _with_filter(run_program(settings["source"], settings["params"], *limits),
                                       settings.get("filter"))
        except PleError as exc:
            _BUILT[key] = str(exc)
        while len(_BUILT) > CACHE_SIZE:
            _BUILT.popitem(last=False)
    lat = _BUILT[key]
    if isinstance(lat, str):
        raise PleError(lat)
    return lat


def npz_bytes(compress: bool = False, **arrays) -> bytes:
    """An ``.npz`` of ``arrays`` whose bytes depend on the arrays only (``np.savez`` stamps the
    time into the zip), so the same part has the same hash on every path and every day."""
    buf = io.BytesIO()
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(buf, "w", method) as zf:
        for name, a in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = method
            with zf.open(info, "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asanyarray(a), allow_pickle=False)
    return buf.getvalue()


# ----- computing one part (runs on a worker) ----------------------------------------------------------
def compute_part(kind: str, settings: dict, part: Part, url: str, limits: tuple | None = None) -> dict:
    """Compute ``part`` and write it under ``url``, the job's program run under ``limits``
    (``Job.limits``); returns its manifest entry. Runs in a worker: everything it needs is in its
    arguments (no state shared with the client)."""
    t0, c0 = time.perf_counter(), time.process_time()
    fs, root = fsspec.core.url_to_fs(url)
    data, extra = _PARTS[kind](settings, part, program_limits(limits))
    write_atomic(fs, posixpath.join(root, part.name), data)
    return {"params": part.params, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(),
            "seconds": round(time.perf_counter() - t0, 4), "cpu_seconds": round(time.process_time() - c0, 4), **extra}


def _sweep_part(settings: dict, part: Part, limits: Limits) -> tuple[bytes, dict]:
    import trimesh
    lat = run_program(settings["source"], part.params, *limits)
    p = pipeline.plan(pipeline.MeshRequest(lat, settings["region"], settings["style"], settings["levels"]))
    mesh = trimesh.Trimesh(*pipeline.mesh(p), process=False)  # the triangles ple mesh writes
    extra = {"triangles": int(len(mesh.faces))}
    if settings["style"] != "balls-beams":
        extra["watertight"] = bool(mesh.is_watertight)
    return mesh_bytes(mesh, settings["format"]), extra


def _mesh_part(settings: dict, part: Part, limits: Limits) -> tuple[bytes, dict]:
    lat = job_lattice(settings, limits)
    p = pipeline.plan(pipeline.MeshRequest(lat, settings["region"], settings["style"], settings["levels"]))
    if part.params.get("unions") or part.params.get("whole"):  # an unclean or group-mapped region: one mesh,
        # with its unions, the triangles ``ple mesh`` writes
        verts, faces = pipeline.mesh(p)
    else:  # one box, on the whole region's float32 grid (as the streamed STL's boxes): the parts close up
        verts, faces = pipeline.box(p, part.params["box"])
    rec = stl_chunk((verts, faces), settings["grid"])
    return STL_HEADER + np.uint32(len(rec)).tobytes() + rec.tobytes(), {"triangles": int(len(rec))}


def _filter_part(settings: dict, part: Part, limits: Limits) -> tuple[bytes, dict]:
    lat = job_lattice(settings, limits)
    box = lat.region(part.params["box"])
    nodes, rows = lat.region_rows(box)
    beam_index, ends = owned_beams(lat, box, rows, lat.region(settings["region"]))
    data = npz_bytes(node_index=nodes.node_index, center=nodes.center, radius=nodes.radius, beam_index=beam_index,
                     beam_ends=ends)
    return data, {"nodes": int(len(nodes.node_index)), "beams": int(len(beam_index))}


def _count_part(settings: dict, part: Part, limits: Limits) -> tuple[bytes, dict]:
    lat = job_lattice(settings, limits)
    nodes, beams = kept_counts(lat, lat.region(part.params["box"]), lat.region(settings["region"]))
    return json.dumps({"box": part.params["box"], "nodes": nodes, "beams": beams}).encode(), {"nodes": nodes,
                                                                                              "beams": beams}


def _slice_part(settings: dict, part: Part, limits: Limits) -> tuple[bytes, dict]:
    lat = job_lattice(settings, limits)
    k0, k1 = part.params["layers"]
    index, zs, masks, filled, width = [], [], [], 0, 0
    for k, z, mask in iter_slices(lambda p: pmc(lat, p), np.array(settings["lo"]), np.array(settings["hi"]),
                                  settings["layer"], settings["pixel"], range(k0, k1)):
        index.append(k)
        zs.append(z)
        masks.append(np.packbits(mask, axis=1))  # 1 bit per pixel, rows padded to bytes
        filled += int(np.count_nonzero(mask))
        width = int(mask.shape[1])
    data = npz_bytes(True, index=np.array(index, np.int64), z=np.array(zs, float), packed=np.array(masks, np.uint8),
                     width=np.int64(width))
    return data, {"layers": len(index), "filled_pixels": filled}


def kept_counts(lat: Lattice, box: Region, region: Region) -> tuple[int, int]:
    """Kept nodes of ``box`` and kept beams whose from-group lies in ``box`` (both ends kept and in
    ``region``). One keep mask over the box grown by the beam offsets (clipped to ``region``) serves
    every beam-pattern: a pattern's beams are the mask and-ed with itself shifted by its offset."""
    offs = np.array([[b.di, b.dj, b.dk] for b in lat.beams], np.int64).reshape(-1, 3)
    b_lo, b_hi = np.array([box.i0, box.j0, box.k0]), np.array([box.i1, box.j1, box.k1])
    r_lo, r_hi = np.array([region.i0, region.j0, region.k0]), np.array([region.i1, region.j1, region.k1])
    lo = np.maximum(b_lo + np.minimum(offs.min(axis=0, initial=0), 0), r_lo)
    hi = np.minimum(b_hi + np.maximum(offs.max(axis=0, initial=0), 0), r_hi)
    halo = Region(int(lo[0]), int(hi[0]), int(lo[1]), int(hi[1]), int(lo[2]), int(hi[2]))
    centers, radii = lat.region_balls(halo)
    keep = lat.keeps(halo.node_index(len(lat.nodes)), centers.reshape(-1, 3), radii.reshape(-1)).reshape(radii.shape)
    del centers, radii
    own = tuple(slice(int(b_lo[a] - lo[a]), int(b_hi[a] - lo[a])) for a in range(3))
    beams = 0
    for b, d in zip(lat.beams, offs):
        s_lo, s_hi = np.maximum(b_lo, r_lo - d), np.minimum(b_hi, r_hi - d)  # from-groups whose far end is in region
        if np.any(s_hi <= s_lo):
            continue
        src = tuple(slice(int(s_lo[a] - lo[a]), int(s_hi[a] - lo[a])) for a in range(3))
        dst = tuple(slice(int(s_lo[a] + d[a] - lo[a]), int(s_hi[a] + d[a] - lo[a])) for a in range(3))
        beams += int(np.count_nonzero(keep[(*src, b.n1)] & keep[(*dst, b.n2)]))
    return int(np.count_nonzero(keep[own])), beams


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


_PARTS = {"sweep": _sweep_part, "mesh": _mesh_part, "filter": _filter_part, "count": _count_part,
          "slice": _slice_part}


# ----- assembling ---------------------------------------------------------------------------------------
def assemble_stl(url: str, out, chunk: int = 1 << 22) -> int:
    """One binary STL of a partitioned mesh: the parts' triangle records concatenated, streamed
    (never all parts in memory). Returns the triangle count."""
    fs, root = location(url, create=False)
    manifest = _complete(url, fs, root, "mesh")
    total = sum(manifest["parts"][p]["triangles"] for p in manifest["order"])
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
    manifest = _complete(url, fs, root, "filter")
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


def count_totals(url: str) -> dict:
    """Kept nodes and beams of a partitioned count job, summed over its parts' manifest entries."""
    fs, root = location(url, create=False)
    manifest = _complete(url, fs, root, "count")
    entries = [manifest["parts"][p] for p in manifest["order"]]
    return {"nodes": sum(e["nodes"] for e in entries), "beams": sum(e["beams"] for e in entries),
            "parts": len(entries)}


def _complete(url: str, fs, root: str, kind: str) -> dict:
    """The manifest of a finished job of ``kind`` (every part present and valid)."""
    manifest = read_manifest(fs, root)
    if manifest.get("kind") != kind:
        raise PleError(f"{url}: not a partitioned {kind} job (kind {echo(manifest.get('kind'))})")
    if not manifest.get("order"):
        raise PleError(f"{url}: the job manifest lists no parts (its \"order\"); re-run the job")
    missing = [p for p in manifest["order"] if p not in valid_parts(fs, root, manifest)]
    if missing:
        raise PleError(f"{url}: {len(missing)} part(s) missing or damaged (e.g. {missing[0]}); re-run the job")
    return manifest


def iter_slice_parts(url: str) -> Iterator[tuple[int, float, np.ndarray]]:
    """(index, z, mask) of every layer of a partitioned slice job, one part in memory at a time."""
    fs, root = location(url, create=False)
    manifest = _complete(url, fs, root, "slice")
    for name in manifest["order"]:
        with fs.open(posixpath.join(root, name), "rb") as fh, np.load(io.BytesIO(fh.read())) as z:
            width = int(z["width"])
            for k, zk, packed in zip(z["index"].tolist(), z["z"].tolist(), z["packed"]):
                yield k, zk, np.unpackbits(packed, axis=1, count=width).astype(bool)


def assemble_slices(url: str, out_dir, progress=None) -> dict:
    """The slice folder of a partitioned slice job (``layer_00000.png`` … and ``manifest.json``),
    the same files as ``ple slice`` writes in one process; returns its manifest."""
    fs, root = location(url, create=False)
    s = _complete(url, fs, root, "slice")["settings"]
    return write_slices(out_dir, iter_slice_parts(url), slice_meta(s["lo"], s["hi"], s["layer"], s["pixel"]), progress)
