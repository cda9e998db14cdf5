"""The filter model of hierarchical lattices (thesis §9): filters, their compounds, filtered evaluation.

A filter decides per node (thesis §9: F(N) -> true/false) from the node's index (i, j, k, n)
and its ball; a beam survives when both of its nodes survive. Filters compose with ``&``,
``|`` and ``~`` and are applied lazily: a filter is part of its lattice (``Lattice.set_filter``,
``lat.with_filter(f)``, or ``FilteredLattice(lat, f)`` in programs), and ``lat.evaluate(region)`` evaluates
only that region of the lattice. A Lattice-in-Lattice (LiL) filter keeps a fine node when
its ball interferes with a coarse lattice (a ball or a cone-beam of it); the coarse lattice
may itself be filtered, which gives the cascades of thesis Fig. 9.3.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod

import numpy as np

from ..errors import PleError
from ..model.lattice import Evaluation, Lattice

MAX_COARSE_NODES = 20_000_000  # a coarse lattice is evaluated in full; beyond this it is not "coarse"
QUERY_CHUNK = 1 << 17  # query balls per vectorized batch (bounds the candidate-pair memory)
THREADS = min(4, os.cpu_count() or 1)
MAX_CELL_ENTRIES = 4_000_000  # (grid cell, element) candidates before the exact reach test


# ----- the filter model ------------------------------------------------------------------------
class Filter(ABC):
    """Decides per node. Subclasses implement ``node_mask``."""

    @abstractmethod
    def node_mask(self, lat: Lattice, node_index: np.ndarray, center: np.ndarray, radius: np.ndarray) -> np.ndarray:
        """bool (N,): which nodes survive, given node_index (N, 4), centres (N, 3) and radii (N,)."""

    def __and__(self, other: Filter) -> Filter:
        return And(self, _as_filter(other))

    def __or__(self, other: Filter) -> Filter:
        return Or(self, _as_filter(other))

    def __invert__(self) -> Filter:
        return Not(self)

    def apply(self, lat: Lattice, region=None) -> Evaluation:
        """The surviving nodes and beams of a region of ``lat`` (default: the whole lattice)."""
        return lat.with_filter(self).evaluate(region)


def _as_filter(f) -> Filter:
    if not isinstance(f, Filter):
        raise PleError(f"cannot combine a filter with {type(f).__name__}")
    return f


class And(Filter):
    """A node survives when every part keeps it (evaluated left to right on the survivors)."""

    def __init__(self, *parts: Filter) -> None:
        self.parts = parts

    def node_mask(self, lat, node_index, center, radius):
        keep = np.ones(len(node_index), dtype=bool)
        for part in self.parts:
            rows = np.flatnonzero(keep)  # later parts only see nodes still alive (LiL is the costly one)
            if rows.size == 0:
                break
            keep[rows] = part.node_mask(lat, node_index[rows], center[rows], radius[rows])
        return keep


class Or(Filter):
    """A node survives when any part keeps it."""

    def __init__(self, *parts: Filter) -> None:
        self.parts = parts

    def node_mask(self, lat, node_index, center, radius):
        keep = np.zeros(len(node_index), dtype=bool)
        for part in self.parts:
            rows = np.flatnonzero(~keep)
            if rows.size == 0:
                break
            keep[rows] = part.node_mask(lat, node_index[rows], center[rows], radius[rows])
        return keep


class Not(Filter):
    def __init__(self, part: Filter) -> None:
        self.part = part

    def node_mask(self, lat, node_index, center, radius):
        return ~self.part.node_mask(lat, node_index, center, radius)


def FilteredLattice(lattice: Lattice, node_filter: Filter) -> Lattice:  # noqa: N802 - program API name
    """``lattice`` seen through ``node_filter`` (and-ed after its own filter): a Lattice, so it is
    evaluated, queried, measured and meshed like any other (thesis §9)."""
    if not isinstance(lattice, Lattice):
        raise PleError(f"a filtered lattice needs a Lattice, got {type(lattice).__name__}")
    return lattice.with_filter(_as_filter(node_filter))


def all_of(*filters) -> Filter | None:
    """The filter keeping what every given filter keeps (None entries are skipped; None if
    none is left): how a program's own filter and the filters added by a command, a LiL
    level or the add-on's panel are composed, left to right."""
    parts = [_as_filter(f) for f in filters if f is not None]
    if not parts:
        return None
    return parts[0] if len(parts) == 1 else And(*parts)
