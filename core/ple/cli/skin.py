"""``ple skin LATTICE --body MESH --thickness T [--cleanup] --out F.stl``: a body's shell of thickness T united
with the lattice that fills it (by ``--fill``, default any) into one watertight solid."""

from __future__ import annotations

from ..errors import PleError
from ..filters.body import body_of
from ..io.export import export_mesh
from ..meshing.skin import skin
from ..meshing.styles import STYLES
from ..meshing.tessellate import tessellate
from .common import add_lattice_args, lattice_from_args

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
    args.skin = args.thickness if args.thickness is not None else args.skin
    if args.skin is None:
        raise PleError("ple skin needs --thickness T")
    lat = lattice_from_args(args)
    if lat.node_count() > MAX_SKIN_NODES:
        raise PleError(f"{lat.node_count():,} nodes (limit {MAX_SKIN_NODES:,} for a skinned mesh)")
    body = body_of(lat, "ple skin")
    solid = skin(body, args.skin, tessellate(lat, style=args.style, cut=False), args.edge)
    export_mesh(solid, args.out)
    print(f"wrote {args.out}: {len(solid.faces):,} triangles, volume {solid.volume:.6g}, "
          f"watertight {solid.is_watertight}")
    return 0

