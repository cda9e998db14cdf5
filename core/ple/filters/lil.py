"""Lattice-in-Lattice filters (thesis §9, Fig. 9.3): a fine node survives where its ball meets a
coarse lattice (or a filtered one, for cascades)."""

from __future__ import annotations

import numpy as np

from ..errors import PleError, echo
from ..model.lattice import Evaluation, Lattice
from ..queries import biq
from ..queries.element_grid import ElementSet
from .base import Filter, all_of

MAX_COARSE_NODES = 20_000_000  # a coarse lattice is evaluated in full; beyond this it is not "coarse"


def evaluate_all(coarse: Lattice) -> Evaluation:
    """All kept elements of a (filtered) coarse lattice, with a size guard."""
    if coarse.node_count() > MAX_COARSE_NODES:
        raise PleError(f"coarse lattice has {coarse.node_count():,} nodes (limit {MAX_COARSE_NODES:,}); "
                       "a LiL coarse lattice is evaluated in full")
    return coarse.evaluate()


class LiL(Filter):
    """Lattice-in-Lattice: a fine node survives when its ball interferes with a ball or a
    cone-beam of ``coarse`` (a Lattice; a filtered one makes a cascade, thesis Fig. 9.3).

    ``method``: ``elements`` evaluates the coarse lattice's kept elements and queries a grid
    over them; ``biq`` calls ``ple.queries.biq.any_hit`` (RangeFinder BIQs against the coarse
    program, removed elements never hit); ``auto`` picks ``elements``, which measured faster
    (docs/filters.md)."""

    def __init__(self, coarse, method: str = "auto") -> None:
        if not isinstance(coarse, Lattice):
            raise PleError(f"LiL coarse must be a Lattice (filtered or not), got {type(coarse).__name__}")
        if method not in ("auto", "elements", "biq"):
            raise PleError(f"LiL method {echo(method)}: expected auto, elements or biq")
        coarse.validate()
        self.coarse = coarse
        self.method = "elements" if method == "auto" else method
        self._index: ElementSet | None = None

    def element_index(self, reach: float) -> ElementSet:
        """The grid over the coarse elements, built once for query radii up to ``reach``."""
        if self._index is None or self._index.reach < reach:
            self._index = ElementSet.from_evaluation(evaluate_all(self.coarse), reach)
        return self._index

    def node_mask(self, lat, node_index, center, radius):
        if len(center) == 0:
            return np.zeros(0, dtype=bool)
        if self.method == "biq":
            return np.asarray(biq.any_hit(self.coarse, center, radius), dtype=bool)
        reach = max(float(np.max(radius)), max_radius(lat))
        return self.element_index(reach).any_hit(center, radius)


def max_radius(lat: Lattice) -> float:
    """Largest ball radius of the lattice (closed form: the extreme group factors are at the
    corners of the index box, since the factor is s_U**i s_V**j s_W**k)."""
    nu, nv, nw = lat.counts
    f = max(lat.U.factor ** i * lat.V.factor ** j * lat.W.factor ** k
            for i in (0, nu - 1) for j in (0, nv - 1) for k in (0, nw - 1))
    grade = lat.radius_field.bound if lat.radius_field is not None else 1.0  # graded radii: their bound
    return float(lat.placement.factor * f * lat.template_radii.max() * grade)


def lil(fine: Lattice, *coarse: Lattice, extra: Filter | None = None, method: str = "auto") -> Lattice:
    """Cascaded LiL: ``lil(F, M, C)`` is F filtered by (M filtered by C), finest to coarsest.
    ``extra`` (e.g. a Stencil) is and-ed into the finest level. A program filter carried by any
    of the lattices (``Lattice.set_filter``) is and-ed into its own level."""
    if not coarse:
        raise PleError("LiL needs at least one coarse lattice")
    current = coarse[-1]
    for medium in reversed(coarse[:-1]):
        current = medium.with_filter(LiL(current, method="elements"))
    top: Filter = LiL(current, method=method if len(coarse) == 1 else "elements")
    return fine.with_filter(all_of(extra, top))
