"""Design rules of a printable lattice (``ple check``): clean (no overlapping non-incident elements,
CHoCC paper §1), thinnest beam and smallest gap against a minimum feature size, beam slenderness,
dangling beams, isolated balls, connected components. Each rule reports whether it holds, a count
and its worst offenders' indices; a filtered lattice is checked on its kept elements, a region on
the elements with both ends inside it."""

from __future__ import annotations

import numpy as np

from ..errors import PleError
from ..model.lattice import Evaluation, Lattice
from ..queries.overlaps import similar_axes, unclean_pairs

MAX_CHECK_ELEMENTS = 20_000_000  # nodes + beams evaluated by one check (memory bound)
QUICK_ELEMENTS = 300_000  # is_clean evaluates at most this many elements (a quick look)
WORST = 10


def _evaluation(lat: Lattice, region) -> Evaluation:
    r = lat.region(region)
    total = r.groups * len(lat.nodes) + lat.beam_count() * r.groups / max(1, lat.groups)
    if total > MAX_CHECK_ELEMENTS:
        raise PleError(f"checking {total:.3g} elements is more than the limit {MAX_CHECK_ELEMENTS:.0e}: "
                       f"check a --region")
    return lat.evaluate(r)


def is_clean(lat: Lattice, region=None, max_elements: int = QUICK_ELEMENTS) -> bool | None:
    """Whether the lattice (its kept part when filtered, or a region) has no unclean pair, for
    one-line warnings in ``ple info`` and ``ple mesh``; None when the answer would cost more than
    a quick look: the unfiltered whole lattice is checked through its anchors when U, V and W are
    all similar (regular lattices, any size), anything else only when it has at most
    ``max_elements`` nodes and beams to evaluate (``ple check`` always answers)."""
    lat.validate()
    whole = lat.filter is None and region is None and lat.becots is None
    if whole and all(similar_axes(lat)):
        return unclean_pairs(lat, path="steady")["clean"]
    r = lat.region(region)
    if (r.groups * len(lat.nodes) + lat.beam_count() * r.groups / max(1, lat.groups)) > max_elements:
        return None
    return unclean_pairs(lat, lat.evaluate(r))["clean"]


def _label(ev: Evaluation, kind: str, rows) -> list[dict]:
    table = ev.node_index if kind == "ball" else ev.beam_index
    return [{kind: [int(x) for x in table[r]]} for r in rows]


def check_lattice(lat: Lattice, region=None, min_feature: float | None = None,
                  max_slenderness: float | None = None) -> dict:
    """{"ok", "filtered", "region", "nodes", "beams", "rules": {name: {"ok", "count", "value",
    "limit", "worst"}}} — see the module doc. ``min_feature`` (model units, e.g. mm) bounds the
    thinnest beam diameter and the smallest gap; ``max_slenderness`` bounds length / diameter."""
    lat.validate()
    for name, value in (("--min-feature", min_feature), ("--max-slenderness", max_slenderness)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise PleError(f"{name} must be a positive number, got {value!r}")
    ev = _evaluation(lat, region)
    rules = {}
    margin = float(min_feature) if min_feature is not None else float(np.median(ev.radius)) if len(ev.radius) else 0.0
    whole = lat.filter is None and region is None and lat.becots is None
    pairs = unclean_pairs(lat, None if whole else ev, margin=margin)
    rules["clean"] = {"ok": pairs["clean"], "count": pairs["unclean_pairs"], "value": pairs["pairs"],
                      "limit": None, "worst": pairs["worst"], "path": pairs["path"]}
    gap = pairs["min_gap"]
    rules["smallest_gap"] = {"ok": min_feature is None or gap is None or gap >= min_feature,
                             "count": int(gap is not None and min_feature is not None and gap < min_feature),
                             "value": gap, "limit": min_feature, "searched_within": margin,
                             "worst": [pairs["min_gap_pair"]] if pairs["min_gap_pair"] else []}
    a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
    diameter = 2 * np.minimum(ev.radius[a], ev.radius[b])
    length = np.linalg.norm(ev.center[b] - ev.center[a], axis=1)
    slender = length / diameter
    order = np.argsort(diameter)[:WORST]
    thin = diameter < min_feature if min_feature is not None else np.zeros(len(diameter), bool)
    rules["thinnest_beam"] = {"ok": not thin.any(), "count": int(thin.sum()),
                              "value": float(diameter.min()) if len(diameter) else None, "limit": min_feature,
                              "worst": _label(ev, "beam", order[thin[order]] if min_feature is not None else order[:1])}
    order = np.argsort(-slender)[:WORST]
    over = slender > max_slenderness if max_slenderness is not None else np.zeros(len(slender), bool)
    rules["slenderness"] = {"ok": not over.any(), "count": int(over.sum()),
                            "value": float(slender.max()) if len(slender) else None, "limit": max_slenderness,
                            "worst": _label(ev, "beam",
                                            order[over[order]] if max_slenderness is not None else order[:1])}
    degree = np.bincount(ev.beam_nodes.reshape(-1), minlength=len(ev.radius))
    for name, deg in (("dangling_beams", 1), ("isolated_balls", 0)):
        rows = np.nonzero(degree == deg)[0]
        rules[name] = {"ok": len(rows) == 0, "count": int(len(rows)), "value": int(len(rows)), "limit": 0,
                       "worst": _label(ev, "ball", rows[:WORST])}
    n_parts, sizes, reps = components(len(ev.radius), ev.beam_nodes)
    small = np.argsort(sizes)[:WORST]
    rules["components"] = {"ok": n_parts <= 1, "count": int(n_parts), "value": int(n_parts), "limit": 1,
                           "worst": [{"ball": _label(ev, "ball", [reps[c]])[0]["ball"], "balls": int(sizes[c])}
                                     for c in small] if n_parts > 1 else []}
    r = lat.region(region)
    return {"ok": all(rule["ok"] for rule in rules.values()), "filtered": lat.filter is not None,
            "region": str(r), "nodes": int(len(ev.radius)), "beams": int(len(ev.beam_nodes)), "rules": rules}


def components(n: int, edges: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """Connected components of n nodes joined by ``edges`` (m, 2): their number, sizes and one
    node of each."""
    if n == 0:
        return 0, np.zeros(0, np.int64), np.zeros(0, np.int64)
    from scipy.sparse import coo_matrix  # noqa: PLC0415 - optional package
    from scipy.sparse.csgraph import connected_components  # noqa: PLC0415

    e = np.asarray(edges, np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    sizes = np.bincount(label, minlength=count)
    first = np.full(count, n, np.int64)
    np.minimum.at(first, label, np.arange(n))
    return int(count), sizes, first
