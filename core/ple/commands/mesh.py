"""``ple mesh LATTICE --style S [--levels N] [--region R] --out F [--beam-lattice] [--check]``."""

from __future__ import annotations

import json
import time

import numpy as np

from ..errors import PleError
from ..export import DEFAULT_UNIT, UNITS, mesh_format, write_beam_lattice_3mf
from ..tessellate import STYLES, tessellate, write_mesh
from .common import add_lattice_args, lattice_from_args

MAX_MESH_GROUPS = 20_000_000  # streamed binary STL
MAX_MEMORY_GROUPS = 500_000  # formats built in memory (trimesh), --check and --beam-lattice
CHECK_SAMPLES = 400_000


def register(sub) -> None:
    p = sub.add_parser("mesh", help="watertight mesh of a region (STL, 3MF, PLY, OBJ, GLB)")
    add_lattice_args(p)
    p.add_argument("--style", choices=STYLES, default="refined",
                   help="tessellation style (default: refined; balls-beams is a preview, not a closed solid)")
    p.add_argument("--levels", type=int, default=None, help="refinement levels of 'refined' (default 4)")
    p.add_argument("--segments", type=int, default=None, help="generators per circle of 'chocc' (default 16)")
    p.add_argument("--region", help="I0:I1,J0:J1,K0:K1 (half-open); default: the whole lattice")
    p.add_argument("--out", required=True, help="output .stl, .3mf, .ply, .obj or .glb")
    p.add_argument("--unit", choices=list(UNITS), default=DEFAULT_UNIT,
                   help="unit of the lattice's coordinates (default mm): written into 3MF, stated in STL/PLY/OBJ; "
                        "glTF is converted to metres")
    p.add_argument("--beam-lattice", action="store_true",
                   help="3MF only: balls and beams with the Beam Lattice extension beside the watertight "
                        "triangle mesh of --style (extensions not required)")
    p.add_argument("--check", action="store_true",
                   help="report, on the file as written and read back: watertightness, winding, Euler "
                        "characteristic, self-intersections and volume vs the lattice's")
    p.set_defaults(func=run)


def run(args) -> int:
    fmt = mesh_format(args.out)
    lat = lattice_from_args(args)
    region = lat.region(args.region)
    if region.groups > MAX_MESH_GROUPS:
        raise PleError(f"region {region} has {region.groups:,} node-groups; choose a smaller --region")
    in_memory = args.check or args.beam_lattice or fmt != "stl"
    if in_memory and region.groups > MAX_MEMORY_GROUPS:
        raise PleError(f"region {region} has {region.groups:,} node-groups: too many to hold in memory for "
                       f".{fmt}{' with --check' if args.check else ''}; write .stl (streamed) or a smaller --region")
    t0 = time.perf_counter()
    if args.beam_lattice and fmt != "3mf":
        raise PleError(f"--beam-lattice writes 3MF; --out {args.out} is .{fmt}")
    info: dict = {}
    if args.beam_lattice:
        from ..filters import evaluate_lattice

        ev = evaluate_lattice(lat, region)
        style = args.style if args.style != "balls-beams" else "refined"
        mesh = tessellate(lat, region, style, args.levels, args.segments)
        _say_unclean(mesh)
        write_beam_lattice_3mf(args.out, ev.center, ev.radius, ev.beam_nodes, mesh=mesh, unit=args.unit)
        print(f"wrote {args.out}: beam lattice, {len(ev.center):,} balls, {len(ev.beam_nodes):,} beams, "
              f"with {len(mesh.faces):,} triangles ({style}), unit {args.unit}")
    elif args.check:
        from ..export import export_mesh

        mesh = tessellate(lat, region, args.style, args.levels, args.segments)
        _say_unclean(mesh)
        n = len(mesh.faces) - export_mesh(mesh, args.out, args.unit)["dropped_faces"]
    else:
        n = write_mesh(lat, args.out, args.style, region, args.levels, args.segments, unit=args.unit, info=info)
        if info.get("unclean") is not None and len(info["unclean"].nodes):
            print(info["unclean"].line())
    dt = time.perf_counter() - t0
    if not args.beam_lattice:
        print(f"wrote {args.out}: {n:,} triangles, style {args.style}, region {region}, unit {args.unit}, "
              f"{dt:.2f} s{' (balls-beams: a preview, not a closed solid)' if args.style == 'balls-beams' else ''}")
    if args.check:
        written = read_back(args.out, args.unit)
        rep = mesh.metadata.get("ple_unclean")
        print(json.dumps(check_report(lat, region, written, unclean=rep is not None and len(rep.nodes) > 0), indent=1))
    return 0


def _say_unclean(mesh) -> None:
    rep = mesh.metadata.get("ple_unclean")
    if rep is not None and len(rep.nodes):
        print(rep.line())


def read_back(path, unit: str = DEFAULT_UNIT):
    """A written mesh file as a consumer reads it: equal coordinates merged into one vertex;
    glTF and OBJ turned back to Z-up and glTF back from metres to ``unit``."""
    import trimesh

    from ..export import UNITS, Y_UP

    fmt = mesh_format(path)
    m = trimesh.load(path, force="mesh", process=False)
    v = np.asarray(m.vertices, float)
    uniq, inv = np.unique(v, axis=0, return_inverse=True)
    f = inv.reshape(-1)[np.asarray(m.faces)]
    if fmt in ("glb", "obj"):
        uniq = uniq @ Y_UP  # the inverse rotation
    if fmt == "glb":
        uniq = uniq / UNITS[unit][1]
    out = trimesh.Trimesh(uniq, f, process=False)
    out.remove_unreferenced_vertices()  # a beam-lattice 3MF also lists the ball centres
    return out


def check_report(lat, region, mesh, unclean: bool = False) -> dict:
    """Watertight, winding, Euler characteristic, self-intersections (exact test,
    ``ple.selfcheck``) and mesh volume against the lattice volume (``ple.measure.lattice_volume``
    for the whole lattice when available, else a Monte Carlo estimate of the union of balls and
    cone-beams in the region, always for an ``unclean`` lattice, whose overlaps the closed form
    would count twice)."""
    from ..selfcheck import count_self_intersections

    rep = {"triangles": int(len(mesh.faces)), "watertight": bool(mesh.is_watertight),
           "winding_consistent": bool(mesh.is_winding_consistent),
           "euler_characteristic": int(mesh.euler_number)}
    rep.update(count_self_intersections(mesh.vertices, mesh.faces))
    rep["mesh_volume"] = float(mesh.volume)
    whole = region == lat.region() and lat.filter is None and not unclean  # the closed form knows no filter
    exact = None
    if whole:
        from ..measure import lattice_volume

        try:
            exact = lattice_volume(lat)
        except PleError:  # e.g. too many hub classes: fall back to the Monte Carlo estimate
            exact = None
        if exact is not None:
            exact = float(exact)
            rep["lattice_volume"], rep["lattice_volume_source"] = exact, "ple.measure.lattice_volume"
    if exact is None:
        est, err = monte_carlo_volume(lat, region)
        rep["lattice_volume"], rep["lattice_volume_source"] = est, f"monte carlo ±{err:.2g}"
        exact = est
    if exact:
        rep["relative_volume_error"] = float(mesh.volume / exact - 1)
    return rep


def monte_carlo_volume(lat, region, samples: int = CHECK_SAMPLES, seed: int = 0) -> tuple[float, float]:
    """Volume of the union of the region's balls and cone-beams by uniform sampling of its box
    (estimate, standard error). Only for --check (the mesh itself never needs it)."""
    from ..achocc import round_cone_distance
    from ..filters import evaluate_lattice

    ev = evaluate_lattice(lat, region)
    lo = (ev.center - ev.radius[:, None]).min(axis=0)
    hi = (ev.center + ev.radius[:, None]).max(axis=0)
    rng = np.random.default_rng(seed)
    p = rng.uniform(lo, hi, size=(samples, 3))
    inside = np.zeros(samples, bool)
    for c, r in zip(ev.center, ev.radius):
        inside |= np.einsum("ij,ij->i", p - c, p - c) <= r * r
    for a, b in ev.beam_nodes:
        box_lo = np.minimum(ev.center[a] - ev.radius[a], ev.center[b] - ev.radius[b])
        box_hi = np.maximum(ev.center[a] + ev.radius[a], ev.center[b] + ev.radius[b])
        sel = np.flatnonzero(np.all((p >= box_lo) & (p <= box_hi), axis=1) & ~inside)
        if len(sel):
            inside[sel] |= round_cone_distance(p[sel], ev.center[a], ev.center[b], ev.radius[a], ev.radius[b]) <= 0
    f = inside.mean()
    vol = float(np.prod(hi - lo))
    return f * vol, vol * float(np.sqrt(f * (1 - f) / samples))
