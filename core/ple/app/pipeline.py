"""One mesh pipeline behind every door: a ``MeshRequest`` (lattice, region, style, levels,
segments, fillet, unit, limits) is planned once (``plan``: normalised, bounds and the float32
output grid computed once, whether the unclean check and its local unions run) and then run
into a sink:

- connectors: ``write_connectors`` (a BeCOTS lattice's connector classes and beams);
- a solid: ``skin_solid`` (a body's shell united with the lattice);
- a file: ``write_mesh`` (STL streamed box by box; PLY, OBJ, 3MF, GLB welded in memory),
  ``write_beam_lattice`` (the beam-lattice 3MF and its fallback triangles);
- arrays: ``stream`` (boxes of float32 vertices on the output grid and int32 faces, the local
  unions of unclean hubs included), ``mesh`` and ``mesh_steps`` (them welded: what the add-on's
  Tessellate draws)
  and ``box`` (one box of the region: a Dask part); ``check`` runs the unclean check alone.

``ple mesh``, ``ple batch``, Dask parts and the add-on's Tessellate and Export all come here, so
that the same request gives the same triangles from every door: the unclean check (CHoCC paper
§6 needs clean hubs; ``ple.meshing.unclean``) runs wherever the region is small enough to check,
and its clusters are united locally (``ple.meshing.unions``). Codecs (``ple.io.export``) only
encode what this module hands them.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

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
from ..io.files import atomic_dir, check_finite_array, check_output_dir, strict_json
from ..io.formats import DEFAULT_UNIT, mesh_format, unit_name
from ..meshing.connectors import constant_radius_connectors
from ..meshing.selfcheck import BLOCK_TRIANGLES
from ..meshing.skin import clip_bodies, skin
from ..meshing.styles import DEFAULT_STYLE
from ..meshing.styles import style as style_named
from ..meshing.tessellate import (
    MAX_CHECK_GROUPS,
    check_bytes,
    check_fillet,
    checked_stream,
    foreseen_union,
    iter_triangles,
    resolve_style,
    smallest_radius,
    tessellate,
    tessellation_box,
    weld_chunks,
)
from ..meshing.weld import grid_spacing, snap, weld
from ..model.budget import (
    CHECK_TRIANGLE_BYTES,
    MESH_TRIANGLE_BYTES,
    Estimate,
    big,
    default_max_memory,
    evaluation_bytes,
    hub_triangles,
    human,
    mean_degree,
    mesh_triangles,
    region_beams,
    region_nodes,
    require,
    streamed_stl_bytes,
)
from ..model.budget import estimate as budget_estimate
from ..model.lattice import Lattice, Region

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh

FALLBACK_STYLES = ("cnt", "chocc", "refined", "none")
DEFAULT_FALLBACK = "cnt"  # the cheapest closed style: a fallback for consumers without beam support


@dataclass(frozen=True)
class MeshRequest:
    """What a door asks for: the mesh of ``region`` of ``lattice`` in ``style``.

    ``levels``/``segments``: refinement levels of refined, generators per circle of chocc (None:
    the defaults); ``fillet``: refined junction fillet in ball radii; ``unit``: the coordinates'
    unit in files; ``max_groups``: node-groups per streamed box at most; ``workers``: threads
    assembling boxes (the output does not depend on them); ``max_memory``: bytes a local union of
    unclean hubs may take (None: the default, ``budget.default_max_memory``, so that every door
    estimates its unions); ``contain``: runs the Booleans that cut a lattice
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
        return f"the {self.style} tessellation of region {self.region}"


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


TRIANGLES_PER_SECOND = 1.0e6  # a CPU-second's triangles, all-unclean lattices included (ple bench unclean: 1.06-1.44 M)


@dataclass(frozen=True)
class MeshEstimate:
    """The work of a plan, before anything is meshed: the one estimate every door checks its
    limits with (``ple mesh``, batch, the add-on's Tessellate and Export).

    ``what``: the triangles and the region in words; ``triangles``
    (``model.budget.mesh_triangles``); ``needs``: (bytes, what, hint) for each
    memory the run holds at once (the mesh in memory, or one node-group's triangles, the
    cleanliness check and, for ``--check``, the file read back), each refused on its own;
    ``memory``: the largest of them; ``disk``: the binary STL's bytes at most (0 when the file is
    not an STL); ``seconds``: at ``TRIANGLES_PER_SECOND``; ``box_groups``: node-groups per streamed
    box such that the boxes alive at once fit ``limit``; ``work``: the add-on's form (balls, beams,
    triangles and the memory of tessellating them in Blender)."""

    what: str
    triangles: int
    needs: tuple
    disk: int
    seconds: float
    box_groups: int
    work: Estimate

    @property
    def memory(self) -> int:
        return int(max((b for b, _, _ in self.needs), default=0))

    def describe(self) -> str:
        return (f"{big(self.triangles)} triangles, about {human(self.memory)} at once, "
                f"{human(self.disk)} of STL, about {self.seconds:.3g} CPU s")


def estimate(p: MeshPlan, fmt: str = "stl", limit: float | None = None, workers: int = 1,
             check_file: bool = False, in_memory: bool | None = None) -> MeshEstimate:
    """The plan's ``MeshEstimate`` for a file of format ``fmt``: streamed box by box when it is a
    binary STL of a steady lattice, else held whole (``in_memory`` says so where the door knows
    better: a skin, a beam lattice, arrays for Blender); ``workers`` threads assembling boxes,
    ``check_file`` the file read back and checked; ``limit`` sizes the boxes."""
    lat, r, style = p.lattice, p.region, p.style
    tris = int(mesh_triangles(lat, r, style, p.levels, p.segments))
    what = f"region {r} ({region_nodes(lat, r):,} nodes)"
    in_memory = (fmt != "stl" or p.cut) if in_memory is None else in_memory
    needs = []
    if check_file:  # the written file, checked block by block (an STL) or read back whole
        per = CHECK_TRIANGLE_BYTES
        needs.append((min(tris, BLOCK_TRIANGLES) * per if fmt == "stl" else tris * per,
                      f"checking {tris:,.3g} triangles ({style}) of {what}",
                      "choose a smaller --region or fewer --levels, or leave out --check"))
    box_groups, disk = 1 << 14, 0
    if in_memory or lat.group_map is not None:  # a group map's region is one box of hubs (Lattice.per_hub)
        how = f"in memory for .{fmt}" if in_memory else f"in one box (a {lat.group_map.kind} lattice is meshed per hub)"
        needs.append((tris * MESH_TRIANGLE_BYTES + evaluation_bytes(lat, r),
                      f"{tris:,.3g} triangles ({style}) of {what} {how}",
                      f"{'write .stl (streamed), ' if in_memory else ''}choose a smaller --region or fewer --levels"))
    else:
        per_group = len(lat.nodes) * hub_triangles(mean_degree(lat), style, p.levels, p.segments) * MESH_TRIANGLE_BYTES
        needs.append((per_group, f"one node-group of {style} mesh", "choose fewer --levels"))
        needs.append((check_bytes(lat, r), f"the cleanliness check of {what}", "choose a smaller --region"))
        disk = int(streamed_stl_bytes(tris))
        if limit is not None:  # the boxes alive at once: one per worker and the one being written
            box_groups = int(max(1, min(1 << 14, limit // (per_group * (workers + 1)))))
    work = budget_estimate(lat, r).with_triangles(tris)
    return MeshEstimate(f"{tris:,.3g} triangles ({style}) of {what}", tris, tuple(needs), disk,
                        tris / TRIANGLES_PER_SECOND, box_groups, work)


BEAM_LATTICE_ELEMENT_BYTES = 150  # per ball and beam of a beam-lattice 3MF, as its XML is streamed


def estimate_beam_lattice(lat: Lattice, region, fallback: str, levels=None, segments=None) -> MeshEstimate:
    """The ``MeshEstimate`` of ``write_beam_lattice``: the region's evaluation, its balls and beams
    as 3MF rows, and the fallback mesh (``"none"``: no triangles) welded in memory."""
    r = lat.region(region)
    tris = 0 if fallback == "none" else int(mesh_triangles(lat, r, fallback,
                                                           *resolve_style(fallback, levels, segments)))
    what = f"region {r} ({region_nodes(lat, r):,} nodes)"
    need = (evaluation_bytes(lat, r) + BEAM_LATTICE_ELEMENT_BYTES * (region_nodes(lat, r) + region_beams(lat, r))
            + tris * MESH_TRIANGLE_BYTES)
    needs = ((need, f"the beam lattice of {what} with {tris:,.3g} triangles ({fallback})",
              "choose a smaller --region, fewer --levels or --fallback cnt"),)
    return MeshEstimate(f"the beam lattice of {what}", tris, needs, 0, tris / TRIANGLES_PER_SECOND, 1 << 14,
                        budget_estimate(lat, r).with_triangles(tris))


def within(est: MeshEstimate, limit: float, folder=None) -> MeshEstimate:
    """``est`` if every memory it needs is within ``limit`` and its STL fits the free space of
    ``folder`` (None: not checked); else a PleError naming the estimate, the limit and the way out."""
    for need, what, hint in est.needs:
        require(need, what, limit, hint)
    free = shutil.disk_usage(folder).free if folder is not None and Path(folder).is_dir() else None
    if free is not None and est.disk > free:
        raise PleError(f"{est.what} make a binary STL of up to {human(est.disk)}, more than the {human(free)} free "
                       f"in {folder}; choose a smaller --region or fewer --levels")
    return est


def _checked(p: MeshPlan, encode=None):
    """(report, chunks) of the plan's checked stream (``checked_stream``): chunks None when the
    region is one mesh in memory (cut at a body)."""
    q = p.request
    return checked_stream(p.lattice, p.region, p.style, p.levels, p.segments, q.max_groups, p.fillet, q.workers,
                          encode=encode, grid=p.grid)


def _foreseen_limit(p: MeshPlan) -> None:
    """Refuse before the unclean check a local union that the balls alone show will pass
    ``max_memory`` (``tessellate.foreseen_union``: overlapping balls, a lower bound)."""
    if not p.checked or p.cut:
        return
    f = foreseen_union(p.lattice, p.region, p.segments)
    if f is not None:
        _union_within(p, f.bytes, "a local union of unclean hubs, foreseen from the balls that overlap", f.hubs,
                      f.beams, f"{f.ball_pairs:,} overlapping balls", f.slabs)


def _union_limit(p: MeshPlan, report) -> None:
    """Refuse before they run the local unions whose largest estimate, with the region's
    evaluation, passes ``max_memory``."""
    if report is not None and report.clusters:  # one local union at a time
        _union_within(p, report.union_bytes, f"the largest of {report.clusters:,} local unions of unclean hubs",
                      report.union_hubs, report.union_beams, f"{report.union_pairs:,} overlapping pairs",
                      report.union_slabs)


def _union_within(p: MeshPlan, peak: int, whose: str, hubs: int, beams: int, pairs: str, slabs: int) -> None:
    """``require`` a union's peak with the region's evaluation within ``max_memory``, naming it."""
    cut = f", cut into {slabs} slabs" if slabs > 1 else ""
    require(peak + evaluation_bytes(p.lattice, p.region),
            f"{whose} ({hubs:,} hubs, {beams:,} beams, {pairs}{cut}), with the region's evaluation, of region "
            f"{p.region}", _limit(p), "choose a smaller --region")


def _limit(p: MeshPlan) -> float:
    """The bytes a local union of the plan may take: its request's ``max_memory``, else the default."""
    return p.request.max_memory if p.request.max_memory is not None else default_max_memory()


def _in_memory(p: MeshPlan, report=None) -> trimesh.Trimesh:
    q = p.request
    return tessellate(p.lattice, p.region, p.style, p.levels, p.segments, fillet=p.fillet, unclean=report,
                      check_clean=p.style != "balls-beams", contain=q.contain)


def _run(p: MeshPlan, encode, info: dict, fmt: str = "float32"):
    """The one sequence every sink runs: the float32 range checked, the unclean check (its
    report in ``info["unclean"]``), the local unions refused when their estimate passes the
    limit; returns the checked stream's boxes, each passed through ``encode`` by the thread that
    assembled it (None: the region is one mesh in memory, cut at a body)."""
    check_float32_range(p.bounds, smallest_radius(p.lattice, p.region), fmt)
    _foreseen_limit(p)
    report, chunks = _checked(p, encode) if not p.cut else (None, None)
    info["unclean"] = report
    _union_limit(p, report)
    return report, chunks


def check(p: MeshPlan):
    """The unclean check of the plan alone (its ``UncleanReport``; None when the plan is not
    checked): what a partitioned job decides its parts by. Nothing is meshed."""
    if not p.checked:
        return None
    report, _ = _checked(p)  # the stream is lazy: only the check runs
    return report


def box(p: MeshPlan, part) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of one box ``part`` of the plan's region (a Dask part): the hubs of the box
    and their beams, on the region's float32 grid, so that the parts close up as the streamed
    file's boxes do. Only for a clean region of a steady lattice (``check``)."""
    return tessellation_box(p.lattice, p.region, part, p.style, p.levels, p.segments, grid=p.grid)


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

    report, chunks = _run(p, keep, info)
    if chunks is None:  # one mesh in memory (cut at a body's surface, or not streamable)
        mesh = _in_memory(p, report)
        info["unclean"] = mesh.metadata.get("ple_unclean")
        v, f, _ = weld(np.asarray(mesh.vertices), np.asarray(mesh.faces), grid)
        yield v.astype(np.float32), f.astype(np.int32)
        return
    yield from chunks


def mesh_steps(p: MeshPlan, info: dict | None = None):
    """The plan's boxes as steps: a generator yielding the fraction of the region's boxes streamed
    so far and returning them joined at their shared grid points (vertices (V, 3) float32 on the
    output grid, faces (F, 3) int32, both C-contiguous): the binary STL's very triangles, indexed.
    A caller shows progress and can stop between boxes."""
    boxes = max(1, -(-p.region.groups // p.request.max_groups))
    chunks = []
    for chunk in stream(p, info):
        chunks.append(chunk)
        yield min(1.0, len(chunks) / boxes)  # the local unions come first: more pieces than boxes
    v, f = weld_chunks(chunks)  # the boxes share their hubs' grid points: the file's very triangles
    chunks.clear()
    return np.ascontiguousarray(v, np.float32), np.ascontiguousarray(f, np.int32)


def mesh(p: MeshPlan, info: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The plan's mesh welded into one (vertices (V, 3) float32 values on the output grid, faces
    (F, 3)): the triangle set of ``write_mesh``'s file of the same request."""
    steps = mesh_steps(p, info)
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            v, f = stop.value
            break
    if p.grid is not None and len(f):  # one indexed mesh: slivers of float32 collapsed (as a PLY's)
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
    report = None
    if fmt == "stl" and p.style != "balls-beams":
        pool = RecordPool()
        report, chunks = _run(p, lambda chunk: stl_chunk(chunk, p.grid, pool), info, fmt)
        if chunks is not None:  # each box encoded by the thread that assembled it; then the unions
            return write_stl(path, chunks, header=stl_header(request.unit), pool=pool)
    elif fmt == "stl":
        return write_stl(path, iter_triangles(p.lattice, p.region, p.style, p.levels, p.segments, request.max_groups,
                                              workers=request.workers),
                         header=stl_header(request.unit), workers=request.workers)
    if p.bounds is not None and fmt != "stl":
        check_float32_range(p.bounds, smallest_radius(p.lattice, p.region), fmt)
    mesh_ = _in_memory(p, report)
    info["unclean"] = mesh_.metadata.get("ple_unclean")
    stats = export_mesh(mesh_, path, request.unit)
    return len(mesh_.faces) - stats["dropped_faces"]  # as written (the weld may drop slivers)


def skin_solid(request: MeshRequest, body, thickness: float, edge: float | None = None) -> trimesh.Trimesh:
    """The request's lattice mesh, not cut at the body (the skin cuts and unites it), united with
    the body's inward shell of ``thickness`` (``meshing.skin.skin``): one closed solid in memory.
    Its Booleans run through ``request.contain`` when given (in a child: a signal stops them at
    once); ``metadata["ple_unclean"]`` is the lattice's unclean report."""
    p = plan(request)
    lattice = tessellate(p.lattice, p.region, p.style, p.levels, p.segments, fillet=p.fillet, cut=False)

    def unite():
        return skin(body, thickness, lattice, edge)

    solid = request.contain(unite) if request.contain is not None else unite()
    solid.metadata["ple_unclean"] = lattice.metadata.get("ple_unclean")
    return solid


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
    import trimesh
    verts, faces = weld_chunks(chunks)
    export_mesh(trimesh.Trimesh(verts, faces, process=False), path, unit)
    return len(faces)


def write_connectors(lat: Lattice, folder, radius: float, beam_radius: float | None = None,
                      grow: float = 0.5, region=None) -> dict:
    """Write one mesh per connector class of a BeCOTS lattice (``connector_<n>.stl``,
    ``meshing.connectors``), the beams as constant-radius cylinders (``beams.stl``) and
    ``connectors.json`` (class keys, instance motions) into ``folder``, complete or not at all."""
    import trimesh
    folder = Path(folder)
    check_output_dir(folder, "ple-connectors")  # ours, new or empty: never another folder's files
    with np.errstate(all="ignore"):  # a non-finite result is refused below, before anything is written
        classes, beams = constant_radius_connectors(lat, radius, beam_radius, grow, region)
        cyl = [trimesh.creation.cylinder(radius=beams["radius"], segment=np.stack([a, b]), sections=12)
               for a, b in zip(beams["start"], beams["end"]) if np.linalg.norm(b - a) > 1e-12]
    what = f"the connectors of radius {radius:g}{f' (beam radius {beam_radius:g})' if beam_radius else ''}"
    for n, cls in enumerate(classes):
        check_finite_array(cls.mesh.vertices, f"{what}: connector {n}")
        check_finite_array(cls.instances, f"{what}: connector {n}'s motions")
    for c in cyl:
        check_finite_array(c.vertices, f"{what}: the beams")
    summary = {"classes": [], "beams": len(beams["start"]), "radius": radius, "beam_radius": beams["radius"]}
    with atomic_dir(folder, "ple-connectors", "ple becots connectors") as tmp:  # complete or not at all
        for n, cls in enumerate(classes):
            name = f"connector_{n}.stl"
            cls.mesh.export(tmp / name, file_type="stl")
            summary["classes"].append({"file": name, "node": cls.key[0], "ends": [list(e) for e in cls.key[1]],
                                       "count": len(cls.instances), "nodes": cls.nodes.tolist(),
                                       "motions": cls.instances.round(12).tolist()})
        if cyl:
            trimesh.util.concatenate(cyl).export(tmp / "beams.stl", file_type="stl")
        (tmp / "connectors.json").write_text(strict_json(summary, "the connectors summary") + "\n")
    return summary
