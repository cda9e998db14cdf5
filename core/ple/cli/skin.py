"""``ple skin LATTICE --body MESH --thickness T [--cleanup] --out F.stl``: a body's shell of thickness T united
with the lattice that fills it (by ``--fill``, default any) into one watertight solid."""

from __future__ import annotations

import math
from functools import partial

from ..app.pipeline import MeshRequest, skin_solid
from ..errors import PleError
from ..filters.body import body_of
from ..io.export import export_mesh
from ..meshing.styles import DEFAULT_LEVELS, DEFAULT_SEGMENTS, STYLES
from ..model.budget import MESH_TRIANGLE_BYTES, evaluation_bytes, mesh_triangles, require
from ..program.meshes import mesh_contained
from .common import add_lattice_args, lattice_from_args, max_memory

MAX_SKIN_NODES = 2_000_000  # the lattice is meshed in memory before the Booleans


def register(sub) -> None:
    p = sub.add_parser("skin", help="a body's shell of thickness T united with the lattice filling it")
    add_lattice_args(p)
    p.add_argument("--thickness", type=float, metavar="T", help="shell thickness (or --skin T)")
    p.add_argument("--edge", type=float, help="edge length of the offset surface (default T/2)")
    p.add_argument("--style", default="refined", choices=[s for s in STYLES if s != "balls-beams"],
                   help="tessellation style of the lattice (default refined)")
    p.add_argument("--out", required=True, help="output mesh (.stl, .3mf, .ply, .obj, .glb)")
    p.set_defaults(func=run, fill="any")


def run(args) -> int:
    if args.body is None:
        raise PleError("ple skin needs --body MESH")
    for flag, v in (("--thickness", args.thickness), ("--edge", args.edge), ("--skin", args.skin)):  # before any work
        if v is not None and not (math.isfinite(v) and v > 0):
            raise PleError(f"{flag} {v}: must be a positive number")
    args.skin = args.thickness if args.thickness is not None else args.skin
    if args.skin is None:
        raise PleError("ple skin needs --thickness T")
    lat = lattice_from_args(args)
    if lat.node_count() > MAX_SKIN_NODES:
        raise PleError(f"{lat.node_count():,} nodes (limit {MAX_SKIN_NODES:,} for a skinned mesh)")
    r = lat.region(None)  # the lattice is meshed in memory, twice (trimesh and manifold3d's copy)
    tris = mesh_triangles(lat, r, args.style, DEFAULT_LEVELS, DEFAULT_SEGMENTS)
    require(2 * tris * MESH_TRIANGLE_BYTES + evaluation_bytes(lat, r),
            f"{tris:,.3g} triangles ({args.style}) of the lattice to skin", max_memory(args),
            "choose a smaller lattice or --style cnt")
    body = body_of(lat, "ple skin")
    request = MeshRequest(lat, None, args.style, contain=partial(mesh_contained, name=args.lattice, what="the skin"))
    solid = skin_solid(request, body, args.skin, args.edge)  # its Booleans in a child: a signal ends them at once
    export_mesh(solid, args.out)
    print(f"wrote {args.out}: {len(solid.faces):,} triangles, volume {solid.volume:.6g}, "
          f"watertight {solid.is_watertight}")
    return 0

