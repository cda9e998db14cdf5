"""``ple filter LATTICE [--stencil S] [--implicit SPEC] [--coarse C] [--region R] --out F.npz|DIR``.

Filters combine with *and*: a node survives when every given filter keeps it; a beam when
both of its nodes survive (thesis §9). ``--out`` ending in ``.npz`` evaluates in memory
(arrays as ``ple eval``); any other ``--out`` is a directory of streamed chunks (ple.io.chunks).
"""

from __future__ import annotations

from ..app.cluster import run_job
from ..app.jobs import count_job, count_totals, filter_job
from ..app.progress import Progress
from ..errors import PleError
from ..filters.base import Filter, all_of
from ..filters.ir import filter_to_dict
from ..filters.lil import lil
from ..io.chunks import DEFAULT_SLAB_GROUPS, stream_filter
from ..io.files import save_npz
from ..model.budget import evaluation_bytes, region_beams, region_nodes, require, slab_groups_within
from ..model.lattice import Lattice
from ..program.sources import load_lattice
from .common import (
    add_cluster_args,
    add_lattice_args,
    contained,
    lattice_from_args,
    limits,
    max_memory,
    parse_implicit,
    parse_stencil,
    report_job,
)
from .eval import MAX_EVAL_GROUPS


def register(sub) -> None:
    p = sub.add_parser("filter", help="filter a lattice (stencil, implicit field, LiL) to .npz or chunks")
    add_lattice_args(p)
    p.add_argument("--stencil", action="append", default=[], metavar="S",
                   help="NAME[:P|PxQxR][:WIDTH] (corners, edges, faces, checker, layers) or a Boolean .npy")
    p.add_argument("--implicit", action="append", default=[], metavar="SPEC",
                   help="KIND[:cell=C,level=L,sheet|network,origin=x/y/z] with KIND gyroid, schwarz_p, "
                        "schwarz_d, diamond, iwp, or fourier:file=COEFFS.npz")
    add_output_args(p)
    p.set_defaults(func=run)


def add_output_args(p) -> None:
    p.add_argument("--coarse", action="append", default=[], metavar="C",
                   help="LiL coarse lattice, SOURCE[:NAME=VALUE,...]; several cascade from finest to coarsest")
    p.add_argument("--region", help="I0:I1,J0:J1,K0:K1 (half-open) of the filtered lattice; default: all")
    p.add_argument("--out", help="output .npz (in memory) or a directory (streamed chunks)")
    p.add_argument("--slab-groups", type=int, default=DEFAULT_SLAB_GROUPS,
                   help=f"node-groups per streamed slab (default {DEFAULT_SLAB_GROUPS})")
    p.add_argument("--method", choices=("auto", "elements", "biq"), default="auto",
                   help="LiL test against the coarsest level (default auto)")
    add_cluster_args(p)
    p.add_argument("--count", action="store_true",
                   help="with --parts: only count the kept nodes and beams, slab by slab (no arrays written; "
                        "the way through a 10⁹-beam lattice)")


def load_coarse(text: str, load=load_lattice):
    """``SOURCE[:NAME=VALUE,...]``: a preset, program or IR with optional program inputs."""
    source, sep, rest = text.partition(":")
    if sep and "=" in rest:
        return load(source, [x for x in rest.split(",") if x])
    return load(text)


def build(args, lat: Lattice, parts: list[Filter]) -> Lattice:
    """``lat`` (with its own filter) filtered by ``parts``, the --stencil and --implicit flags
    and, with --coarse, a LiL cascade."""
    parts = list(parts)
    parts += [parse_stencil(s) for s in getattr(args, "stencil", [])]
    parts += [parse_implicit(s) for s in getattr(args, "implicit", [])]
    extra = all_of(*parts)
    if args.coarse:
        load = contained(args) if hasattr(args, "timeout") else load_lattice
        return lil(lat, *(load_coarse(c, load) for c in args.coarse), extra=extra, method=args.method)
    if extra is None and lat.filter is None:
        raise PleError("no filter given: use --stencil, --implicit or --coarse")
    return lat.with_filter(extra)


def write(args, lat: Lattice) -> int:
    if args.count and not args.parts:
        raise PleError("--count runs as a partitioned job: give --parts URL")
    if args.parts:  # one part per slab, on Dask workers; the filter travels as data
        spec = None if lat.filter is None else filter_to_dict(lat.filter)  # the program's and the flags'
        make = count_job if args.count else filter_job
        job = make(args.lattice, args.param, args.region, args.slab_groups, spec, limits(args))
        status = report_job(run_job(job, args.parts, args.scheduler, args.workers))
        if status == 0 and args.count:
            totals = count_totals(args.parts)
            print(f"kept: {totals['nodes']:,} nodes of {region_nodes(lat, lat.region(args.region)):,}, "
                  f"{totals['beams']:,} beams of {region_beams(lat, lat.region(args.region)):,}")
        return status
    region = lat.region(args.region)
    total = f"of {region.groups * len(lat.nodes):,} nodes"
    if args.out is None or args.out.endswith(".npz"):
        if region.groups * len(lat.nodes) > MAX_EVAL_GROUPS:
            raise PleError(f"region {region} has {region.groups * len(lat.nodes):,} nodes; "
                           "give --out a directory to stream chunks instead of one .npz")
        require(2 * evaluation_bytes(lat, region), f"region {region} ({region_nodes(lat, region):,} nodes, "
                f"{region_beams(lat, region):,} beams)", max_memory(args),
                "choose a smaller --region or give --out a directory to stream chunks")
        ev = lat.evaluate(region)
        if args.out is not None:
            save_npz(args.out, ev.arrays())
        print(f"{'wrote ' + args.out if args.out else 'kept'}: {len(ev.center):,} nodes {total}, "
              f"{len(ev.beam_nodes):,} beams")
        return 0
    bar = Progress(region.groups, "filter")
    manifest = stream_filter(lat, args.out, region, slab_groups_within(lat, args.slab_groups, max_memory(args)),
                             progress=bar)
    print(f"wrote {args.out}/ ({len(manifest['chunks'])} chunks): {manifest['nodes']:,} nodes {total}, "
          f"{manifest['beams']:,} beams")
    return 0


def run(args) -> int:
    if args.out is None and args.parts is None:
        raise PleError("--out is required (a .npz file or a directory for streamed chunks), or --parts URL")
    lat = lattice_from_args(args)
    return write(args, build(args, lat, []))
