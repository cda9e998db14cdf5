"""One cache for the per-lattice plans of the query backends (RangeFinder, BeCOTS RangeFinder):
everything a backend precomputes from the program alone, kept on the lattice object and rebuilt
when the lattice changes (a new key)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from ..model.lattice import Lattice

PLANS_ATTR = "_query_plans"  # slot on the Lattice object: {backend: (key, plan, keepalive)}
T = TypeVar("T")


def lattice_key(lat: Lattice) -> tuple:
    """Everything a plan depends on: counts, similarities (frozen values: equal parameters, equal
    keys), template balls, beam-patterns, the BeCOTS description and the group map (their
    objects are kept alive with the plan, so their ids stay unique)."""
    info = lat.becots
    becots = (id(info), id(getattr(info, "field", None)), getattr(info, "counts", None),
              getattr(info, "closed", None), id(getattr(info, "stack", None)))
    return (lat.counts, (lat.U, lat.V, lat.W, lat.placement), lat.template_centers.tobytes(),
            lat.template_radii.tobytes(), tuple((b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams), becots,
            id(lat.group_map))


def cached(lat: Lattice, backend: str, build: Callable[[Lattice], T]) -> T:
    """``build(lat)``, computed once per lattice state and backend."""
    key = lattice_key(lat)
    plans = lat.__dict__.setdefault(PLANS_ATTR, {})
    hit = plans.get(backend)
    if hit is not None and hit[0] == key:
        return hit[1]
    plan = build(lat)
    plans[backend] = (key, plan, (lat.becots, lat.group_map))
    return plan


def forget(lat: Lattice) -> None:
    """Drop every cached plan of ``lat`` (benchmarks time the cold path with it)."""
    lat.__dict__.pop(PLANS_ATTR, None)
