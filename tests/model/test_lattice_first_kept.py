"""Lattice.first_kept_group: where a drawing of a filtered lattice starts when its first corner
keeps nothing; checked against the whole evaluation's first kept row."""

from __future__ import annotations

import numpy as np
from ple.filters.stencil import Stencil
from ple.program.sources import load_lattice


def test_first_kept_group_is_the_first_kept_row_of_the_whole_evaluation():
    lat = load_lattice("hier_lil3")
    kept = {tuple(map(int, row[:3])) for row in lat.evaluate().node_index}  # the filter asked once, whole
    want = None
    for box in lat.iter_slabs(512, lat.region()):  # the first box holding a kept group, its first one
        hits = [tuple(map(int, row[:3])) for row in box.node_index(len(lat.nodes)) if tuple(map(int, row[:3])) in kept]
        if hits:
            want = hits[0]
            break
    assert want is not None and want != (0, 0, 0)  # the corner keeps nothing: the case it is for
    assert lat.first_kept_group(max_groups=512) == want


def test_without_a_filter_or_keeping_nothing():
    lat = load_lattice("cubic")
    assert lat.first_kept_group() == (0, 0, 0)
    none = lat.with_filter(Stencil(np.zeros((2, 2, 2), bool)))
    assert none.first_kept_group() is None
