"""``ple clg info|pmc|voxelize|slice|ray|render|mesh SOURCE …``: Constructive Lattice Geometry
(thesis §5, §10). SOURCE is a ``ple-clg/1`` file, a program defining ``clg(**params)`` or a CLG preset."""

from __future__ import annotations

import time

import numpy as np

from ..app.progress import Progress
from ..clg.grid import check_grid, layer_grid, parse_bounds, voxel_tiles, voxelize_clg
from ..clg.query import compiled
from ..clg.rays import render, trace
from ..errors import PleError, echo
from ..io.export import export_mesh
from ..io.files import atomic_path, strict_json
from ..io.inputs import load_npy
from ..io.slices import write_pmc_slices
from ..model.budget import require
from ..program.clg_sources import run_clg
from ..program.meshes import mesh_clg_contained
from .common import add_program_limits, limits, max_memory


def _source(p) -> None:
    p.add_argument("source", metavar="SOURCE", help="a ple-clg/1 .json, a program .py defining clg(), or a preset")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="a program input")
    add_program_limits(p)  # a program runs contained: --timeout, --max-memory (docs/reliability.md)


def _action(cmds, name: str, func, help: str):
    """One action's parser: the source arguments and its function."""
    q = cmds.add_parser(name, help=help)
    _source(q)
    q.set_defaults(func=func)
    return q


def register(sub) -> None:
    p = sub.add_parser("clg", help="Constructive Lattice Geometry: PMC, voxels, slices, rays, renders, meshes")
    cmds = p.add_subparsers(dest="clg_command", metavar="ACTION")
    cmds.required = True
    _action(cmds, "info", run_info, "chunks, primitives, materials, nesting depth and the box")
    q = _action(cmds, "pmc", run_pmc, "point membership of points (n, 3) .npy -> bool (n,) .npy")
    q.add_argument("--points", required=True)
    q.add_argument("--out", required=True)
    q = _action(cmds, "voxelize", run_voxelize, "bool voxels (NX, NY, NZ) .npy of the voxel centres")
    q.add_argument("--grid", required=True, metavar="NX,NY,NZ")
    q.add_argument("--bounds", metavar="x0,y0,z0,x1,y1,z1", help="default: the solid's box")
    q.add_argument("--out", required=True)
    q = _action(cmds, "slice", run_slice, "printer slices: one 1-bit PNG per layer + manifest.json")
    add_slice_args(q)
    q = _action(cmds, "ray", run_ray, "first-hit distances of rays (n, 6) .npy -> (n,) .npy (inf: a miss)")
    q.add_argument("--rays", required=True)
    q.add_argument("--out", required=True)
    q = _action(cmds, "render", run_render, "a shaded picture (progressive passes)")
    q.add_argument("--out", required=True, help="output .png")
    q.add_argument("--size", default="640,480", metavar="W,H")
    q.add_argument("--view", default="35,25", metavar="AZIMUTH,ELEVATION", help="degrees")
    q.add_argument("--passes", type=int, default=4)
    q = _action(cmds, "mesh", run_mesh, "a watertight mesh of the solid (manifold3d booleans)")
    q.add_argument("--out", required=True, help="output mesh (.stl, .ply, .obj, .glb, .3mf)")
    q.add_argument("--segments", type=int, default=32, help="circle segments of balls and beams")


def add_slice_args(q, out_required: bool = True) -> None:
    q.add_argument("--layer", type=float, required=True, help="layer height")
    q.add_argument("--pixel", type=float, required=True, help="pixel size")
    q.add_argument("--bounds", metavar="x0,y0,z0,x1,y1,z1", help="default: the solid's box")
    q.add_argument("--out", required=out_required, help="output folder")


def _load(args):
    return compiled(run_clg(args.source, args.param, *limits(args)))


def _npy(path: str, what: str, cols: int) -> np.ndarray:
    a = load_npy(path, what)  # a regular file, header checked first, no archives or pickles (ple.io.inputs)
    if a.ndim != 2 or a.shape[1] != cols or not np.issubdtype(a.dtype, np.number):
        raise PleError(f"{what} {path}: expected a numeric array of shape (n, {cols}), got {a.shape}")
    a = a.astype(float)
    if not np.all(np.isfinite(a)):
        raise PleError(f"{what} {path}: NaN or infinite values")
    return a


def _save_npy(path: str, arr) -> None:
    if not path.endswith(".npy"):
        raise PleError(f"--out {path}: expected a .npy file")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, arr)


def run_info(args) -> int:
    comp = _load(args)
    clg = comp.clg
    lat = clg.pattern
    info = {"chunks": {n: len(comp.leaves[c]) for c, n in enumerate(comp.names)},
            "unused_chunks": sorted(set(clg.chunks) - set(comp.names)), "primitives": clg.primitive_count(),
            "materials": sorted(clg.materials), "depth": clg.depth, "counts": list(lat.counts),
            "becots": lat.becots is not None, "chunk_copies": lat.groups * len(comp.names),
            "similar_copies": comp.similar,
            "box": [comp.lo.tolist(), comp.hi.tolist()],
            "conical_shell": None if comp.shell is None else {
                "apex": comp.shell.apex.tolist(), "axis": comp.shell.axis.tolist(), "phi": list(comp.shell.phi),
                "distance": list(comp.shell.dist)}}
    print(strict_json(info, "the CLG info", indent=1))
    return 0


def run_pmc(args) -> int:
    pts = _npy(args.points, "--points", 3)
    comp = _load(args)
    t0 = time.perf_counter()
    inside = comp.pmc(pts)
    _save_npy(args.out, inside)
    print(f"wrote {args.out}: {int(inside.sum())} of {len(pts)} points inside ({time.perf_counter() - t0:.2f} s)")
    return 0


def run_voxelize(args) -> int:
    try:
        shape = [int(x) for x in args.grid.split(",")]
    except ValueError:
        raise PleError(f"--grid {echo(args.grid)}: expected NX,NY,NZ integers") from None
    if len(shape) != 3:
        raise PleError(f"--grid {echo(args.grid)}: expected NX,NY,NZ")
    if not args.out.endswith(".npy"):
        raise PleError(f"--out {args.out}: expected a .npy file")
    comp = _load(args)
    lo, hi = parse_bounds(args.bounds, comp.lo, comp.hi)
    bar = Progress(voxel_tiles(comp, lo, hi, check_grid(shape)), "voxelize")
    vox = voxelize_clg(comp, lo, hi, shape, bar.update, max_memory(args))
    bar.close()
    _save_npy(args.out, vox)
    print(f"wrote {args.out}: {vox.shape} voxels, {int(vox.sum())} inside")
    return 0


def slice_with(pmc, lo, hi, args) -> int:
    zs, xs, ys = layer_grid(lo, hi, args.layer, args.pixel)
    bar = Progress(len(zs), "slice")
    man = write_pmc_slices(args.out, pmc, lo, hi, args.layer, args.pixel, bar.update)
    bar.close()
    print(f"wrote {args.out}: {man['layers']} layers of {man['image_size'][0]}x{man['image_size'][1]} pixels")
    return 0


def run_slice(args) -> int:
    comp = _load(args)
    lo, hi = parse_bounds(args.bounds, comp.lo, comp.hi)
    return slice_with(comp.pmc, lo, hi, args)


def run_ray(args) -> int:
    rays = _npy(args.rays, "--rays", 6)
    comp = _load(args)
    bar = Progress(len(rays), "rays")
    t = trace(comp, rays[:, :3], rays[:, 3:], progress=bar.update)
    bar.close()
    _save_npy(args.out, t)
    print(f"wrote {args.out}: {int(np.isfinite(t).sum())} of {len(t)} rays hit")
    return 0


def _pair(text: str, what: str, kind=float):
    try:
        a, b = (kind(x) for x in text.split(","))
    except ValueError:
        raise PleError(f"{what} {echo(text)}: expected two numbers A,B") from None
    return a, b


RENDER_PIXEL_BYTES = 200


def run_render(args) -> int:
    try:
        from PIL import Image
    except ImportError:
        raise PleError("render needs Pillow (pip install pillow)") from None
    size = _pair(args.size, "--size", int)
    view = _pair(args.view, "--view")
    if not all(np.isfinite(view)):
        raise PleError(f"--view {echo(args.view)}: expected two finite angles")
    if min(size) < 1 or size[0] * size[1] > 1 << 24:
        raise PleError(f"--size {echo(args.size)}: expected 1..16M pixels")
    # camera rays (48 B), the picture and its masks, and one pass's trace temporaries
    require(size[0] * size[1] * RENDER_PIXEL_BYTES, f"--size {args.size}: a {size[0]}x{size[1]} picture",
            max_memory(args), "choose a smaller --size")
    if args.passes < 1 or args.passes > 8:
        raise PleError(f"--passes {args.passes}: expected 1..8")
    comp = _load(args)
    bar = Progress(size[0] * size[1], "render")

    def show(k, img):
        bar.update(0, f"pass {k + 1}/{args.passes}")
    t0 = time.perf_counter()
    img = render(comp, size, view, args.passes, bar.update, show)
    bar.close()
    with atomic_path(args.out) as tmp:
        Image.fromarray(img).save(tmp, format="PNG")
    print(f"wrote {args.out}: {size[0]}x{size[1]} in {time.perf_counter() - t0:.1f} s")
    return 0


def run_mesh(args) -> int:
    import trimesh
    comp = _load(args)
    verts, faces = mesh_clg_contained(comp, args.segments, max_memory(args), args.source)  # a signal ends it at once
    mesh = trimesh.Trimesh(verts, faces, process=False)
    export_mesh(mesh, args.out)
    print(f"wrote {args.out}: {len(mesh.faces)} triangles, volume {mesh.volume:.6g}, "
          f"watertight {mesh.is_watertight}")
    return 0
