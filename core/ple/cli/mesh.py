"""``ple mesh LATTICE --style S [--levels N] [--region R] --out F [--unit U] [--beam-lattice] [--check]``."""

from __future__ import annotations

import os
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np

from ..algebra.elements import beam_distance
from ..app.cluster import run_job
from ..app.jobs import assemble_stl, mesh_job
from ..app.pipeline import (
    DEFAULT_FALLBACK,
    FALLBACK_STYLES,
    MeshRequest,
    estimate,
    estimate_beam_lattice,
    plan,
    skin_solid,
    within,
    write_beam_lattice,
    write_mesh,
)
from ..errors import PleError
from ..filters.body import body_of
from ..io.export import STL_RECORD, export_mesh, read_back
from ..io.files import strict_json
from ..io.formats import DEFAULT_UNIT, UNITS, mesh_format
from ..io.spill import SpillFiles
from ..measure.check import is_clean, solid_volume
from ..meshing.selfcheck import check_triangles
from ..meshing.styles import DEFAULT_STYLE, STYLE_NAMES
from ..meshing.tessellate import check_fillet, resolve_style, tessellate
from ..model.budget import (
    human,
    streamed_stl_bytes,
)
from ..program.meshes import mesh_contained
from .common import add_cluster_args, add_lattice_args, lattice_from_args, limits, max_memory, report_job

MAX_MESH_GROUPS = 20_000_000  # streamed binary STL
MAX_MEMORY_GROUPS = 500_000  # formats built in memory (trimesh) and --beam-lattice
CHECK_SAMPLES = 400_000
DEFAULT_MESH_BYTES = 16 << 30  # refined without --levels: the finest level whose STL is at most this (_default_levels)
CHECK_CHUNK = 1 << 18  # triangles read from the written STL at a time by --check


def register(sub) -> None:
    p = sub.add_parser("mesh", help="watertight mesh of a region (STL, 3MF, PLY, OBJ, GLB)")
    add_lattice_args(p)
    p.add_argument("--style", choices=STYLE_NAMES, default=None,
                   help=f"tessellation style (default: {DEFAULT_STYLE}; balls-beams is a preview, not a closed solid)")
    p.add_argument("--levels", type=int, default=None,
                   help="refinement levels of 'refined' (default 4; when the budgets refuse it, the finest they "
                        "take, up to 16 GiB of STL)")
    p.add_argument("--segments", type=int, default=None, help="generators per circle of 'chocc' (default 16)")
    p.add_argument("--region", help="I0:I1,J0:J1,K0:K1 (half-open); default: the whole lattice")
    p.add_argument("--fillet", type=float, default=None,
                   help="'refined' only: junction fillet size in ball radii (CHoCC paper Eq. 6)")
    p.add_argument("--out", help="output .stl, .3mf, .ply, .obj or .glb (with --parts: the assembled .stl)")
    p.add_argument("--unit", choices=tuple(UNITS), default=DEFAULT_UNIT,
                   help=f"unit of the lattice's coordinates (default {DEFAULT_UNIT}): written into 3MF, stated in "
                        "STL/PLY/OBJ; glTF is converted to metres")
    p.add_argument("--box-groups", type=int, default=1 << 14, metavar="N",
                   help="with --parts: node-groups per part (default 16384)")
    add_cluster_args(p, "; without --parts, threads assembling the streamed STL's boxes (the same file for any number)")
    p.add_argument("--beam-lattice", action="store_true",
                   help="3MF only: balls and beams with the Beam Lattice extension beside a watertight "
                        "triangle mesh, the fallback of consumers without beam support (extensions not required)")
    p.add_argument("--fallback", choices=FALLBACK_STYLES, default=None,
                   help=f"with --beam-lattice: the style of the fallback triangle mesh (default: --style if given, "
                        f"else {DEFAULT_FALLBACK}, the cheapest closed style); none: beams only, the extensions "
                        "required")
    p.add_argument("--check", action="store_true",
                   help="report, on the file as written and read back (an STL in blocks: bounded memory): "
                        "watertightness, winding, Euler characteristic, exact self-intersections, and the "
                        "mesh volume vs the lattice's (ple info's)")
    p.set_defaults(func=run)


def run(args) -> int:
    fallback_style(args)  # before --style gets its default
    args.style = args.style or DEFAULT_STYLE
    check_fillet(args.fillet, args.style)  # before any work
    if args.fillet and (args.parts or args.beam_lattice):
        raise PleError("--fillet shapes a single mesh file of style refined (not --parts or --beam-lattice)")
    if args.parts:
        return run_parts(args)
    if not args.out:
        raise PleError("give --out FILE (or --parts URL for a partitioned mesh)")
    fmt = mesh_format(args.out)
    lat = lattice_from_args(args)
    region = lat.region(args.region)
    if region.groups > MAX_MESH_GROUPS:
        raise PleError(f"region {region} has {region.groups:,} node-groups; choose a smaller --region")
    in_memory = args.beam_lattice or fmt != "stl" or args.skin is not None or (args.check and lat.group_map is not None)
    if in_memory and region.groups > MAX_MEMORY_GROUPS:
        raise PleError(f"region {region} has {region.groups:,} node-groups: too many to hold in memory for "
                       f".{fmt}; write .stl (streamed) or a smaller --region")
    max_groups = _default_levels(args, lat, region, fmt, in_memory)
    t0 = time.perf_counter()
    if args.beam_lattice and fmt != "3mf":
        raise PleError(f"--beam-lattice writes 3MF; --out {args.out} is .{fmt}")
    info: dict = {}
    contain = partial(mesh_contained, name=args.lattice, what="the cut at the body")  # a signal stops its Booleans
    if args.skin is not None:  # the body's shell united with the lattice: one solid, in memory
        if args.beam_lattice or args.check:
            raise PleError("--skin makes one solid of shell and lattice: not with --beam-lattice or --check")
        style = args.style if args.style != "balls-beams" else "refined"
        request = MeshRequest(lat, region, style, args.levels, args.segments,
                              contain=partial(mesh_contained, name=args.lattice, what="the skin"))
        mesh = skin_solid(request, body_of(lat, "--skin"), args.skin)  # the skin cuts and unites the lattice
        info["unclean"] = mesh.metadata.get("ple_unclean")
        n = len(mesh.faces) - export_mesh(mesh, args.out, args.unit)["dropped_faces"]
    elif args.beam_lattice:
        request = MeshRequest(lat, region, args.fallback if args.fallback != "none" else DEFAULT_FALLBACK,
                              args.levels, args.segments, unit=args.unit, max_groups=max_groups,
                              workers=stream_workers(args.workers), max_memory=max_memory(args), contain=contain)
        got = write_beam_lattice(request, args.out, args.fallback, info)
        if info["unclean"] is not None and len(info["unclean"].nodes):
            print(info["unclean"].line())
        mesh_text = (f"with {got['triangles']:,} triangles ({args.fallback})" if args.fallback != "none"
                     else "without a triangle mesh (--fallback none: the beam extensions are required)")
        print(f"wrote {args.out}: beam lattice, {got['balls']:,} balls, {got['beams']:,} beams, {mesh_text}, "
              f"unit {args.unit}")
    elif args.check and lat.group_map is not None:  # groups placed by a map: checked in memory
        mesh = tessellate(lat, region, args.style, args.levels, args.segments, fillet=args.fillet, contain=contain)
        info["unclean"] = _say_unclean(mesh)
        n = len(mesh.faces) - export_mesh(mesh, args.out, args.unit)["dropped_faces"]
    else:
        request = MeshRequest(lat, region, args.style, args.levels, args.segments, args.fillet, args.unit, max_groups,
                              stream_workers(args.workers), max_memory(args), contain)
        n = write_mesh(request, args.out, info)
        if info.get("unclean") is not None and len(info["unclean"].nodes):
            print(info["unclean"].line())
    dt = time.perf_counter() - t0
    if not args.beam_lattice:
        print(f"wrote {args.out}: {n:,} triangles, style {args.style}, region {region}, unit {args.unit}, "
              f"{dt:.2f} s{' (balls-beams: a preview, not a closed solid)' if args.style == 'balls-beams' else ''}")
    # the mesher's own check of the region (``ple.meshing.unclean``) answers when it ran; the
    # design-rule check runs only when it did not (balls-beams, regions too large to check)
    report = info.get("unclean")
    if report is not None and report.pairs:
        print(f"warning: the lattice is not clean ({report.pairs:,} pairs of elements that share no ball have "
              "overlapping mesh hulls): ple check lists the pairs", file=sys.stderr)
    elif report is None and is_clean(lat, region) is False:
        print("warning: the lattice is not clean (elements overlap elements they share no ball with): ple check "
              "lists the pairs", file=sys.stderr)
    if args.check:
        rep = check_report(lat, region, args.out, args.unit, unclean=report is not None and len(report.nodes) > 0)
        print(volume_line(rep))
        print(strict_json(rep, indent=1))
    return 0


def run_parts(args) -> int:
    """The mesh as binary-STL parts, one per box of node-groups, computed by Dask workers;
    with --out, assembled into one STL."""
    if args.check or args.beam_lattice or args.skin is not None:
        raise PleError("--parts writes triangle parts: --check, --beam-lattice and --skin need a single file")
    if args.unit != DEFAULT_UNIT:
        raise PleError(f"--parts writes STL parts in {DEFAULT_UNIT}; --unit {args.unit} needs a single file")
    if args.out and mesh_format(args.out) != "stl":
        raise PleError(f"--out {args.out}: a partitioned mesh assembles into binary .stl")
    if args.box_groups < 1:
        raise PleError(f"--box-groups must be at least 1, got {args.box_groups}")
    job = mesh_job(args.lattice, args.param, args.style, args.levels, args.region, args.box_groups, limits(args))
    if job.settings["unclean"]:
        print(f"{job.settings['unclean']}: one part")
    status = report_job(run_job(job, args.parts, args.scheduler, args.workers))
    if status == 0 and args.out:
        n = assemble_stl(args.parts, args.out)
        print(f"wrote {args.out}: {n:,} triangles from {len(job.parts)} parts")
    return status


def _default_levels(args, lat, region, fmt: str, in_memory: bool) -> int:
    """``_within_budget``, with the refinement chosen when --levels is not given: the default
    (4) if its mesh fits the budgets (memory, disk), else the finest level that does with at most
    DEFAULT_MESH_BYTES of STL, else 0 levels if it fits the budgets (said on stderr). A lattice of
    10⁶ hubs (the thesis presets: 0.7-1.6 TiB at 4 levels) is thus meshed at the levels it can
    be, not refused; an explicit --levels is kept, or refused as before. Nothing fits: the
    default's refusal."""
    if args.levels is not None or args.style != "refined" or args.beam_lattice:
        return _within_budget(args, lat, region, fmt, in_memory)
    default, segments = resolve_style(args.style, None, args.segments)
    why = None
    for levels, capped in [(default, False), *((k, True) for k in range(default - 1, -1, -1)), (0, False)]:
        args.levels = levels
        est = _estimate(args, lat, region, fmt, in_memory)  # the pipeline's one estimate, at these levels
        tris = est.triangles
        try:
            if capped and streamed_stl_bytes(tris) > DEFAULT_MESH_BYTES:
                raise PleError(f"{tris:,.3g} triangles make up to {human(streamed_stl_bytes(tris))} of binary STL, "
                               f"more than {human(DEFAULT_MESH_BYTES)}")
            got = within(est, max_memory(args), Path(args.out).resolve().parent).box_groups
        except PleError as exc:
            why = why or exc
            continue
        if levels < default:
            print(f"note: refined at {default} levels (the default): {why}; meshing at {levels} levels, up to "
                  f"{human(streamed_stl_bytes(tris))} of STL (--levels chooses)", file=sys.stderr)
        return got
    args.levels = None
    return _within_budget(args, lat, region, fmt, in_memory)  # nothing fits: the default's own refusal


def _estimate(args, lat, region, fmt: str, in_memory: bool):
    """The pipeline's estimate of the mesh the arguments ask for (``pipeline.estimate``, or
    ``estimate_beam_lattice`` for --beam-lattice), its boxes sized to fit --max-memory."""
    if args.beam_lattice:  # balls and beams, and the triangle mesh that rides along in the 3MF
        return estimate_beam_lattice(lat, region, args.fallback, args.levels, args.segments)
    request = MeshRequest(lat, region, args.style, *resolve_style(args.style, args.levels, args.segments))
    return estimate(plan(request), fmt, max_memory(args), stream_workers(args.workers), args.check, in_memory)


def _within_budget(args, lat, region, fmt: str, in_memory: bool) -> int:
    """Refuse a mesh whose estimated memory (or, streamed, file) exceeds the limits; returns the
    node-groups per streamed box so that the boxes alive at once (--workers + 1) fit the memory
    limit."""
    folder = None if args.beam_lattice else Path(args.out).resolve().parent
    return within(_estimate(args, lat, region, fmt, in_memory), max_memory(args), folder).box_groups


def fallback_style(args) -> None:
    """``args.fallback``: the beam lattice's fallback mesh, --fallback or else an explicit closed --style
    or else DEFAULT_FALLBACK (cnt: the triangles of a beam lattice are for consumers without beam
    support, and cnt is the cheapest closed style); --fallback without --beam-lattice is refused."""
    if not args.beam_lattice:
        if args.fallback is not None:
            raise PleError("--fallback is the triangle mesh of --beam-lattice; without it, use --style")
        return
    if args.fallback is None:
        args.fallback = args.style or DEFAULT_FALLBACK
    elif args.style is not None and args.style != args.fallback:
        raise PleError(f"--style {args.style} and --fallback {args.fallback}: with --beam-lattice, give one")
    if args.fallback not in FALLBACK_STYLES:
        raise PleError(f"--beam-lattice: the fallback mesh needs a closed style ({', '.join(FALLBACK_STYLES)}), "
                       f"not {args.fallback}")


def stream_workers(n: int | None) -> int:
    """Threads assembling the streamed STL's boxes: --workers, default the cores."""
    if n is not None and n < 1:
        raise PleError(f"--workers {n}: expected at least 1")
    return int(n or os.cpu_count() or 1)


def _say_unclean(mesh):
    """Print the mesh's unclean-hub line (if any); returns its report (None: not checked)."""
    rep = mesh.metadata.get("ple_unclean")
    if rep is not None and len(rep.nodes):
        print(rep.line())
    return rep


def check_report(lat, region, path, unit: str = DEFAULT_UNIT, unclean: bool = False) -> dict:
    """The written mesh file checked as a consumer reads it (``ple.meshing.selfcheck.check_triangles``:
    watertight, winding, Euler characteristic, exact self-intersections, faces without area; an
    STL read in chunks and checked in blocks, memory bounded), and its volume against the lattice's:
    the volume ``ple info`` reports (``ple.measure.check.solid_volume``: the union of balls and
    cone-beams of a clean lattice), else, for an ``unclean`` lattice whose overlaps it would count
    twice, or one too varied to measure, a Monte Carlo estimate of the union in the region."""
    with SpillFiles(Path(path).resolve().parent) as blocks:  # beside the file: as much room as it took
        c = check_triangles(lambda: file_triangles(path, unit), store=blocks)
    rep = {k: c[k] for k in ("triangles", "watertight", "winding_consistent", "euler_characteristic",
                             "self_intersecting_pairs", "self_intersecting_faces", "degenerate_faces")}
    rep["mesh_volume"] = float(c["volume"])
    try:
        solid = None if unclean else solid_volume(lat, region)
    except PleError:  # e.g. too many hubs to measure: the Monte Carlo estimate
        solid = None
    if solid is not None:
        err = f" ±{solid['error']:.2g}" if solid["error"] is not None else ""
        rep["lattice_volume"], rep["lattice_volume_source"] = solid["volume"], f"ple info ({solid['method']}){err}"
    else:
        est, err = monte_carlo_volume(lat, region)
        rep["lattice_volume"], rep["lattice_volume_source"] = est, f"monte carlo ±{err:.2g}"
    if rep["lattice_volume"]:
        rep["relative_volume_error"] = float(rep["mesh_volume"] / rep["lattice_volume"] - 1)
    return rep


def volume_line(rep: dict) -> str:
    """The mesh volume beside the lattice's, and their difference in percent."""
    diff = f": difference {100 * rep['relative_volume_error']:+.3f} %" if "relative_volume_error" in rep else ""
    return (f"volume: mesh {rep['mesh_volume']:.9g}, lattice {rep['lattice_volume']:.9g} "
            f"({rep['lattice_volume_source']}){diff}")


def file_triangles(path, unit: str = DEFAULT_UNIT, chunk: int = CHECK_CHUNK):
    """Triangles (k, 3, 3) of a written mesh file in PLE's axes and ``unit``: a binary STL's
    float32 corners ``chunk`` records at a time (never the whole file), other formats read back
    whole (``ple.io.export.read_back``)."""
    if mesh_format(path) != "stl":
        m = read_back(path, unit)
        yield np.asarray(m.vertices)[np.asarray(m.faces)]
        return
    n = int(np.fromfile(path, "<u4", count=1, offset=80)[0])
    records = np.memmap(path, STL_RECORD, mode="r", offset=84, shape=(n,))
    for i in range(0, n, chunk):
        yield np.array(records["vertices"][i:i + chunk])  # a copy: the map's pages can go


def monte_carlo_volume(lat, region, samples: int = CHECK_SAMPLES, seed: int = 0) -> tuple[float, float]:
    """Volume of the union of the region's balls and cone-beams by uniform sampling of its box
    (estimate, standard error). Only for --check (the mesh itself never needs it). Each ball and
    beam tests only the samples in the grid cells of its box (``SampleGrid``): the same points
    pass as when every element tested every sample."""

    ev = lat.evaluate(region)
    lo = (ev.center - ev.radius[:, None]).min(axis=0)
    hi = (ev.center + ev.radius[:, None]).max(axis=0)
    rng = np.random.default_rng(seed)
    p = rng.uniform(lo, hi, size=(samples, 3))
    ends = np.asarray(ev.beam_nodes, np.int64).reshape(-1, 2)
    lo_end, hi_end = ev.center - ev.radius[:, None], ev.center + ev.radius[:, None]
    beam_lo = np.minimum(lo_end[ends[:, 0]], lo_end[ends[:, 1]])
    beam_hi = np.maximum(hi_end[ends[:, 0]], hi_end[ends[:, 1]])
    grid = SampleGrid(p, lo, hi, np.concatenate([2 * ev.radius, (beam_hi - beam_lo).max(axis=1)]))
    p, inside = grid.points, np.zeros(samples, bool)
    for c, r in zip(ev.center, ev.radius):
        sel = grid.within(c - r, c + r)
        inside[sel] |= np.einsum("ij,ij->i", p[sel] - c, p[sel] - c) <= r * r
    for (a, b), box_lo, box_hi in zip(ends, beam_lo, beam_hi):
        sel = grid.within(box_lo, box_hi)
        sel = sel[np.all((p[sel] >= box_lo) & (p[sel] <= box_hi), axis=1) & ~inside[sel]]
        if len(sel):
            inside[sel] |= beam_distance(p[sel], ev.center[a], ev.radius[a], ev.center[b], ev.radius[b]) <= 0
    f = inside.mean()
    vol = float(np.prod(hi - lo))
    return f * vol, vol * float(np.sqrt(f * (1 - f) / samples))


class SampleGrid:
    """Sample points (n, 3) in the box ``lo``..``hi``, sorted into a uniform grid of cells about
    the median size of the elements that will ask for them (``sizes``), so that an element finds
    the samples near it without testing all n. ``points`` holds them in cell order."""

    def __init__(self, points: np.ndarray, lo, hi, sizes: np.ndarray) -> None:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        extent = np.maximum(hi - lo, 1e-300)
        size = float(np.median(sizes)) if len(sizes) else float(extent.max())
        cells = np.clip(np.ceil(extent / max(size, 1e-300)), 1, 1 + np.cbrt(len(points))).astype(np.int64)
        self.lo, self.cells, self.step = lo, cells, extent / cells
        # a box is widened by a hair before its cells are found: a point on its face, rounded
        # either way, is still among the samples it is given
        self.pad = 1e-9 * (np.abs(lo) + np.abs(hi) + extent)
        key = self._key(self._cell(points))
        order = np.argsort(key, kind="stable")
        self.points = points[order]
        self.starts = np.searchsorted(key[order], np.arange(cells.prod() + 1))

    def _cell(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.floor((x - self.lo) / self.step).astype(np.int64), 0, self.cells - 1)

    def _key(self, ijk: np.ndarray) -> np.ndarray:
        return (ijk[..., 0] * self.cells[1] + ijk[..., 1]) * self.cells[2] + ijk[..., 2]

    def within(self, box_lo, box_hi) -> np.ndarray:
        """int (m,): rows of ``points`` in the cells that the box ``box_lo``..``box_hi`` meets (a
        superset of the points inside it)."""
        (i0, j0, k0), (i1, j1, k1) = self._cell(box_lo - self.pad).tolist(), self._cell(box_hi + self.pad).tolist()
        nj, nk = int(self.cells[1]), int(self.cells[2])
        column = [(i * nj + j) * nk for i in range(i0, i1 + 1) for j in range(j0, j1 + 1)]
        return np.concatenate([np.arange(self.starts[c + k0], self.starts[c + k1 + 1]) for c in column])
