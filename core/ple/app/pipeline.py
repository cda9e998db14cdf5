"""One mesh pipeline behind every door: a ``MeshRequest`` (lattice, region, style, levels,
segments, fillet, unit, limits) is planned once (``plan``: normalised, bounds and the float32
output grid computed once, whether the unclean check and its local unions run) and then run
into a sink:

- a file: ``write_mesh`` (STL streamed box by box; PLY, OBJ, 3MF, GLB welded in memory),
  ``write_beam_lattice`` (the beam-lattice 3MF and its fallback triangles);
- arrays: ``stream`` (boxes of float32 vertices on the output grid and int32 faces, the local
  unions of unclean hubs included: what the add-on's Tessellate draws) and ``mesh`` (them welded).

``ple mesh``, ``ple batch``, Dask parts and the add-on's Tessellate and Export all come here, so
that the same request gives the same triangles from every door: the unclean check (CHoCC paper
§6 needs clean hubs; ``ple.meshing.unclean``) runs wherever the region is small enough to check,
and its clusters are united locally (``ple.meshing.unions``). Codecs (``ple.io.export``) only
encode what this module hands them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh

from ..errors import PleError, echo
from ..io.export import (
    RecordPool,
    check_float32_range,
    export_mesh,
    prepare_closed,
    stl_chunk,
    stl_header,
    write_3mf,
    write_stl,
)
from ..io.formats import DEFAULT_UNIT, mesh_format, unit_name
from ..meshing.skin import clip_bodies
from ..meshing.styles import DEFAULT_STYLE
from ..meshing.styles import style as style_named
from ..meshing.tessellate import (
    MAX_CHECK_GROUPS,
    check_fillet,
    checked_stream,
    iter_triangles,
    resolve_style,
    smallest_radius,
    tessellate,
    weld_chunks,
)
from ..meshing.weld import grid_spacing, snap, weld
from ..model.budget import evaluation_bytes, require
from ..model.lattice import Lattice, Region

FALLBACK_STYLES = ("cnt", "chocc", "refined", "none")
DEFAULT_FALLBACK = "cnt"  # the cheapest closed style: a fallback for consumers without beam support


@dataclass(frozen=True)
class MeshRequest:
    """What a door asks for: the mesh of ``region`` of ``lattice`` in ``style``.

    ``levels``/``segments``: refinement levels of refined, generators per circle of chocc (None:
    the defaults); ``fillet``: refined junction fillet in ball radii; ``unit``: the coordinates'
    unit in files; ``max_groups``: node-groups per streamed box at most; ``workers``: threads
    assembling boxes (the output does not depend on them); ``max_memory``: bytes a local union of
    unclean hubs may take (None: unlimited); ``contain``: runs the Booleans that cut a lattice
    filling a body by ``any`` (``ple.program.meshes.mesh_contained``)."""

    lattice: Lattice
    region: Region | str | None = None
    style: str = DEFAULT_STYLE
    levels: int | None = None
    segments: int | None = None
    fillet: float | None = None
    unit: str = DEFAULT_UNIT
    max_groups: int = 1 << 14
    workers: int = 1
    max_memory: float | None = None
    contain: Callable | None = None


@dataclass(frozen=True)
class MeshPlan:
    """A request normalised once: its region, style settings, bounds (None for the preview
    style), the float32 ``grid`` every box and file of the region is snapped to, and whether the
    unclean check runs (``checked``) and the body cut (``cut``)."""

    request: MeshRequest
    region: Region
    style: str
    levels: int
    segments: int
    fillet: float | None
    bounds: np.ndarray | None
    grid: float | None
    checked: bool
    cut: bool

    @property
    def lattice(self) -> Lattice:
        return self.request.lattice

    def describe(self) -> str:
        return f"the {self.style} mesh of region {self.region}"


def plan(request: MeshRequest) -> MeshPlan:
    """Normalise ``request`` once (style, levels, segments, fillet, unit, region, bounds, grid);
    a bad value is a PleError naming it."""
    style_named(request.style)
    unit_name(request.unit)
    levels, segments = resolve_style(request.style, request.levels, request.segments)
    fillet = check_fillet(request.fillet, request.style)
    lat = request.lattice
    r = lat.region(request.region)
    bounds = np.array(lat.bounds(r)) if request.style != "balls-beams" else None
    grid = grid_spacing(*bounds) if bounds is not None else None
    cut = bool(clip_bodies(lat))
    checked = request.style != "balls-beams" and not cut and r.groups <= MAX_CHECK_GROUPS
    return MeshPlan(request, r, request.style, levels, segments, fillet, bounds, grid, checked, cut)


def _checked(p: MeshPlan, encode=None):
    """(report, chunks) of the plan's checked stream (``checked_stream``): chunks None when the
    region is one mesh in memory (cut at a body)."""
    q = p.request
    return checked_stream(p.lattice, p.region, p.style, p.levels, p.segments, q.max_groups, p.fillet, q.workers,
                          encode=encode, grid=p.grid)


def _union_limit(p: MeshPlan, report) -> None:
    """Refuse before they run the local unions whose largest estimate, with the region's
    evaluation, passes ``max_memory``."""
    q = p.request
    if report is not None and report.clusters and q.max_memory is not None:  # one local union at a time
        require(report.union_bytes + evaluation_bytes(p.lattice, p.region),
                f"the largest of {report.clusters:,} local unions of unclean hubs, with the region's "
                f"evaluation, of region {p.region}", q.max_memory, "choose a smaller --region")


def _in_memory(p: MeshPlan, report=None) -> trimesh.Trimesh:
    q = p.request
    return tessellate(p.lattice, p.region, p.style, p.levels, p.segments, fillet=p.fillet, unclean=report,
                      check_clean=p.style != "balls-beams", contain=q.contain)


def stream(p: MeshPlan, info: dict | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The plan's mesh as boxes (vertices float32 (V, 3) on the output grid, faces int32 (F, 3)):
    the triangles a file of it holds, the local unions of unclean hubs first. ``info["unclean"]``
    gets the check's report (None: not checked) once the first box is asked for."""
    info = {} if info is None else info
    if p.style == "balls-beams":  # a preview: not snapped, not checked
        info["unclean"] = None
        for v, f in iter_triangles(p.lattice, p.region, p.style, p.levels, p.segments, p.request.max_groups):
            yield np.asarray(v, np.float32), np.asarray(f, np.int32)
        return
    grid = p.grid

    def keep(chunk):  # in the assembling thread: the stream reuses the box's arrays once this returns
        verts, faces = chunk
        return snap(verts, grid).astype(np.float32), np.array(faces, np.int32)  # copies

    check_float32_range(p.bounds, smallest_radius(p.lattice, p.region), "float32")
    report, chunks = _checked(p, keep) if not p.cut else (None, None)
    info["unclean"] = report
    _union_limit(p, report)
    if chunks is None:  # one mesh in memory (cut at a body's surface, or not streamable)
        mesh = _in_memory(p, report)
        info["unclean"] = mesh.metadata.get("ple_unclean")
        v, f, _ = weld(np.asarray(mesh.vertices), np.asarray(mesh.faces), grid)
        yield v.astype(np.float32), f.astype(np.int32)
        return
    yield from chunks


def mesh(p: MeshPlan, info: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The plan's mesh welded into one (vertices (V, 3) float32 values on the output grid, faces
    (F, 3)): the triangle set of ``write_mesh``'s file of the same request."""
    v, f = weld_chunks(stream(p, info))
    if p.grid is not None and len(f):
        v, f, _ = weld(v, f, p.grid)
    return v, f


def write_mesh(request: MeshRequest, path, info: dict | None = None) -> int:
    """The request's mesh straight to ``path`` (format from the suffix); returns the number of
    triangles written. Binary STL streams box by box (memory bounded by a box and a local union,
    boxes assembled by ``workers`` threads, the same file for any number), every box snapped to
    the region's float32 grid; the other formats build the mesh in memory and go through
    ``ple.io.export.export_mesh``. Regions up to ``MAX_CHECK_GROUPS`` groups are checked for
    unclean hubs first; their local unions are refused (PleError, no file) when the largest one's
    estimate passes ``max_memory``. ``info["unclean"]`` gets the report (None when not checked)."""
    p = plan(request)
    fmt = mesh_format(path)
    info = {} if info is None else info
    info["unclean"] = None
    if p.bounds is not None:
        check_float32_range(p.bounds, smallest_radius(p.lattice, p.region), fmt)
    report = None
    if fmt == "stl" and p.style != "balls-beams":
        pool = RecordPool()
        report, chunks = _checked(p, lambda chunk: stl_chunk(chunk, p.grid, pool)) if not p.cut else (None, None)
        info["unclean"] = report
        _union_limit(p, report)
        if chunks is not None:  # each box encoded by the thread that assembled it; then the unions
            return write_stl(path, chunks, header=stl_header(request.unit), pool=pool)
    elif fmt == "stl":
        return write_stl(path, iter_triangles(p.lattice, p.region, p.style, p.levels, p.segments, request.max_groups,
                                              workers=request.workers),
                         header=stl_header(request.unit), workers=request.workers)
    mesh_ = _in_memory(p, report)
    info["unclean"] = mesh_.metadata.get("ple_unclean")
    stats = export_mesh(mesh_, path, request.unit)
    return len(mesh_.faces) - stats["dropped_faces"]  # as written (the weld may drop slivers)


def write_beam_lattice(request: MeshRequest, path, fallback: str = DEFAULT_FALLBACK, info: dict | None = None) -> dict:
    """A region's balls and cone beams as a 3MF Beam Lattice beside its watertight triangle mesh
    of style ``fallback`` (``FALLBACK_STYLES``), which a consumer without beam support prints;
    ``"none"`` writes the beams alone (the file then requires the extensions). The fallback is
    this pipeline's ``mesh`` of the request in that style (checked, unions included), welded
    into one indexed mesh. ``info["unclean"]`` gets the report (None: not checked, or no
    fallback). Returns {"balls", "beams", "triangles"}."""
    if mesh_format(path) != "3mf":
        raise PleError(f"{path}: a beam lattice is written as .3mf")
    if fallback not in FALLBACK_STYLES:
        raise PleError(f"fallback mesh {echo(fallback)}: expected one of {', '.join(FALLBACK_STYLES)}")
    unit_name(request.unit)
    lat = request.lattice
    info = {} if info is None else info
    info["unclean"] = None
    v, f = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    r = lat.region(request.region)
    if fallback != "none":
        p = plan(replace(request, style=fallback, region=r))
        check_float32_range(p.bounds, smallest_radius(lat, r), "3mf")
        if p.cut:  # one mesh cut at the body: kept closed through float32 as every closed file is
            mesh_ = _in_memory(p)
            info["unclean"] = mesh_.metadata.get("ple_unclean")
            v, f, _ = prepare_closed(mesh_, "3mf", request.unit, p.grid, Path(path).name)
        else:
            v, f = mesh(p, info)
    ev = lat.evaluate(r)
    write_3mf(path, v, f, unit_name(request.unit), (ev.center, ev.radius, ev.beam_nodes))
    return {"balls": len(ev.center), "beams": len(ev.beam_nodes), "triangles": len(f)}


def write_chunks(path, chunks, unit: str = DEFAULT_UNIT) -> int:
    """Boxes (pairs vertices, faces) written as one mesh, welded by ``weld_chunks``, in the format
    of ``path``'s suffix; returns the number of triangles."""
    verts, faces = weld_chunks(chunks)
    export_mesh(trimesh.Trimesh(verts, faces, process=False), path, unit)
    return len(faces)
