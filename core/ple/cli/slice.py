"""``ple slice LATTICE --layer H --pixel P --out DIR/``: printer slices of a plain lattice (1-bit PNGs +
manifest), streamed layer by layer through the RangeFinder's PMC. With ``--parts URL`` the layers
are a partitioned job on Dask (one part per ``--layers-per-part`` layers); ``--out`` then gets the
assembled folder, the same files as the one-process run."""

from __future__ import annotations

import numpy as np

from ..app.cluster import run_job
from ..app.jobs import assemble_slices, slice_job
from ..clg.grid import parse_bounds
from ..errors import PleError
from ..filters.ir import filter_to_dict
from ..model.budget import fast_bounds
from ..queries.biq import pmc
from .clg import add_slice_args, slice_with
from .common import add_cluster_args, add_lattice_args, lattice_from_args, limits, report_job


def register(sub) -> None:
    p = sub.add_parser("slice", help="printer slices of a lattice: one 1-bit PNG per layer + manifest.json")
    add_lattice_args(p)
    add_slice_args(p, out_required=False)
    p.add_argument("--layers-per-part", type=int, default=32, metavar="N",
                   help="with --parts: layers per part (default 32)")
    add_cluster_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    if not args.out and not args.parts:
        raise PleError("give --out DIR (or --parts URL for a partitioned slice job)")
    lat = lattice_from_args(args)
    if args.bounds is None:
        lo, hi, exact = fast_bounds(lat)  # end groups only where exact: a huge lattice answers at once
        if not exact:
            lo, hi = lat.bounds()
    else:
        lo, hi = parse_bounds(args.bounds, None, None)
    if args.parts:
        spec = None if lat.filter is None else filter_to_dict(lat.filter)
        job = slice_job(args.lattice, args.param, args.layer, args.pixel, (lo, hi), args.layers_per_part, spec,
                        limits(args))
        status = report_job(run_job(job, args.parts, args.scheduler, args.workers))
        if status == 0 and args.out:
            man = assemble_slices(args.parts, args.out)
            print(f"wrote {args.out}: {man['layers']} layers of {man['image_size'][0]}x{man['image_size'][1]} "
                  f"pixels from {len(job.parts)} parts")
        return status
    return slice_with(lambda p: pmc(lat, p), np.asarray(lo, float), np.asarray(hi, float), args)
