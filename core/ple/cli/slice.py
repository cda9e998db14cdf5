"""``ple slice LATTICE --layer H --pixel P --out DIR/``: printer slices of a plain lattice (1-bit PNGs +
manifest), streamed layer by layer through the RangeFinder's PMC."""

from __future__ import annotations

import numpy as np

from ..clg.grid import parse_bounds
from ..model.budget import fast_bounds
from ..queries.biq import pmc
from .clg import add_slice_args, slice_with
from .common import add_lattice_args, lattice_from_args


def register(sub) -> None:
    p = sub.add_parser("slice", help="printer slices of a lattice: one 1-bit PNG per layer + manifest.json")
    add_lattice_args(p)
    add_slice_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    lat = lattice_from_args(args)
    if args.bounds is None:
        lo, hi, exact = fast_bounds(lat)  # end groups only where exact: a huge lattice answers at once
        if not exact:
            lo, hi = lat.bounds()
    else:
        lo, hi = parse_bounds(args.bounds, None, None)
    return slice_with(lambda p: pmc(lat, p), np.asarray(lo, float), np.asarray(hi, float), args)
