"""Design rules of a printable lattice (``ple check``): clean (no overlapping non-incident elements,
CHoCC paper §1), thinnest beam and smallest gap against a minimum feature size, beam slenderness,
dangling beams, isolated balls, connected components. Each rule reports whether it holds, a count
and its worst offenders' indices; a filtered lattice is checked on its kept elements, a region on
the elements with both ends inside it."""

from __future__ import annotations

import numpy as np

from ..errors import PleError, echo
from ..model.lattice import Evaluation, Lattice
from ..queries.overlaps import PairLimitError, similar_axes, unclean_pairs
from .integrals import kept_measures, lattice_measures
from .moments import mass_properties

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
        try:
            return unclean_pairs(lat, path="steady", first=True)["clean"]
        except PairLimitError:  # its anchors overlap too many elements for a quick look
            return None
    r = lat.region(region)
    if (r.groups * len(lat.nodes) + lat.beam_count() * r.groups / max(1, lat.groups)) > max_elements:
        return None
    try:
        return unclean_pairs(lat, lat.evaluate(r), first=True)["clean"]
    except PairLimitError:  # elements of sizes too far apart for one grid, or overlapping too many
        return None


def solid_volume(lat: Lattice, region=None) -> dict | None:
    """The volume ``ple info`` reports for what the lattice keeps in ``region``: {"volume",
    "error" (the quadrature's estimate, 3σ; None when not estimated), "method"}; the union of the
    balls and cone-beams when the lattice is clean (its hubs have disjoint interiors). None when
    it is not measured (too many hub classes)."""
    r = lat.region(region)
    if lat.group_map is not None:  # groups placed by a map: area and volume per hub
        props = lattice_measures(lat) if str(r) == str(lat.region()) else kept_measures(lat, r)
        method, error = props.get("area_method", ""), None
    else:
        props = mass_properties(lat, r)
        method, error = props.get("method", ""), props.get("quadrature_error")
    if props.get("volume") is None:
        return None
    return {"volume": float(props["volume"]), "error": None if error is None else float(error), "method": method}


def _label(ev: Evaluation, kind: str, rows) -> list[dict]:
    table = ev.node_index if kind == "ball" else ev.beam_index
    return [{kind: [int(x) for x in table[r]]} for r in rows]


def check_lattice(lat: Lattice, region=None, min_feature: float | None = None,
                  max_slenderness: float | None = None, max_pairs: float | None = None) -> dict:
    """{"ok", "filtered", "region", "nodes", "beams", "rules": {name: {"ok", "count", "value",
    "limit", "worst"}}} — see the module doc. ``min_feature`` (model units, e.g. mm) bounds the
    thinnest beam diameter and the smallest gap; ``max_slenderness`` bounds length / diameter;
    ``max_pairs`` the candidate pairs the clean rule may test (``ple.queries.overlaps.check_pairs``,
    None: its default)."""
    lat.validate()
    for name, value in (("--min-feature", min_feature), ("--max-slenderness", max_slenderness),
                        ("--max-pairs", max_pairs)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise PleError(f"{name} must be a positive number, got {echo(value)}")
    ev = _evaluation(lat, region)
    rules = {}
    margin = float(min_feature) if min_feature is not None else float(np.median(ev.radius)) if len(ev.radius) else 0.0
    whole = lat.filter is None and region is None and lat.becots is None
    pairs = unclean_pairs(lat, None if whole else ev, margin=margin, max_pairs=max_pairs)
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


def check_report(lat: Lattice, region=None, min_feature: float | None = None,
                 max_slenderness: float | None = None) -> dict:
    """``check_lattice`` with the mass properties of what is checked (``mass_properties``: area,
    volume, centroid, inertia about the centroid; None when they were skipped): the report of
    the add-on's Check panel."""
    out = check_lattice(lat, region, min_feature, max_slenderness)
    props = {} if lat.group_map is not None else mass_properties(lat, region)
    out["mass"] = None if "volume" not in props else {
        k: (np.asarray(props[k]).tolist() if props[k] is not None else None)
        for k in ("area", "volume", "centroid", "inertia", "quadrature_error")}
    return out


RULE_NAMES = {"clean": "clean (no overlapping non-incident elements)", "thinnest_beam": "thinnest beam diameter",
              "smallest_gap": "smallest gap between non-incident elements", "slenderness": "beam slenderness L/d",
              "dangling_beams": "dangling beams (ball with one beam)", "isolated_balls": "isolated balls",
              "components": "connected components"}


def rule_lines(report: dict, offenders: int = 5) -> list[tuple[str, bool, str, list[str]]]:
    """The report as text, one entry per rule: (key, ok, "name: value", offender lines) — what
    ``ple check`` prints and the add-on's panel shows."""
    out = []
    for key, rule in report["rules"].items():
        worst = [] if rule["ok"] else [offender_text(w) for w in rule["worst"][:offenders]]
        out.append((key, bool(rule["ok"]), f"{RULE_NAMES[key]}: {_value(key, rule)}", worst))
    return out


def _value(key: str, rule: dict) -> str:
    limit = f" (limit {rule['limit']:g})" if isinstance(rule.get("limit"), float) else ""
    if key == "clean":
        kinds = ", ".join(f"{n:,} {k.replace('_', '–')}" for k, n in rule["value"].items() if n)
        return f"{rule['count']:,} unclean pairs" + (f" ({kinds})" if kinds else "")
    if key == "smallest_gap":
        if rule["value"] is None:
            return f"none closer than {rule['searched_within']:.4g}{limit}"
        return f"{rule['value']:.4g}{limit}"
    if key in ("thinnest_beam", "slenderness"):
        v = "no beams" if rule["value"] is None else f"{rule['value']:.4g}"
        return v + limit + (f", {rule['count']:,} beams beyond" if rule["count"] else "")
    return f"{rule['count']:,}"


def offender_text(w: dict) -> str:
    """One offender of a rule: an element, or a pair of elements with its depth and copies."""
    parts = [f"{kind} {tuple(idx)}" for side in ("a", "b") if side in w for kind, idx in w[side].items()]
    if parts:
        extra = f" depth {w['depth']:.3g}" if "depth" in w else ""
        copies = f", {w['count']:,} similar copies" if w.get("count", 1) > 1 else ""
        return f"{w.get('kind', '')} {' × '.join(parts)}{extra}{copies}".strip()
    (kind, idx), = ((k, v) for k, v in w.items() if k in ("ball", "beam"))
    return f"{kind} {tuple(idx)}" + (f" ({w['balls']} balls)" if "balls" in w else "")


def offender_region(lat: Lattice, w: dict, pad: int = 1):
    """The index region around an offender (its elements' groups, a beam's far group too),
    grown by ``pad`` groups and clamped to the lattice: where to look at it."""
    lat.validate()
    groups = []
    for kind, idx in ((k, v) for part in (w.get("a", {}), w.get("b", {}), w) for k, v in part.items()
                      if k in ("ball", "beam")):
        g = np.array(idx[:3], np.int64)
        groups.append(g)
        if kind == "beam":
            if not 0 <= idx[3] < len(lat.beams):
                raise PleError(f"offender {w}: no beam-pattern {idx[3]}")
            groups.append(g + np.array(lat.beams[idx[3]].offset))
    if not groups:
        raise PleError(f"offender {w}: no ball or beam indices")
    lo = np.maximum(np.min(groups, axis=0) - pad, 0)
    hi = np.minimum(np.max(groups, axis=0) + 1 + pad, lat.counts)
    return lat.region(",".join(f"{a}:{b}" for a, b in zip(lo, hi)))


def components(n: int, edges: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """Connected components of n nodes joined by ``edges`` (m, 2): their number, sizes and one
    node of each (scipy's, or numpy's min-label hooking where scipy is missing, e.g. in Blender)."""
    if n == 0:
        return 0, np.zeros(0, np.int64), np.zeros(0, np.int64)
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    try:
        from scipy.sparse import coo_matrix  # noqa: PLC0415 - optional package
        from scipy.sparse.csgraph import connected_components  # noqa: PLC0415
    except ImportError:
        label = _min_labels(n, e)
    else:
        graph = coo_matrix((np.ones(len(e), np.int8), (e[:, 0], e[:, 1])), shape=(n, n))
        label = connected_components(graph, directed=False)[1]
    _, label = np.unique(label, return_inverse=True)
    count = int(label.max()) + 1
    sizes = np.bincount(label, minlength=count)
    first = np.full(count, n, np.int64)
    np.minimum.at(first, label, np.arange(n))
    return count, sizes, first


def _min_labels(n: int, e: np.ndarray) -> np.ndarray:
    """Per node the smallest node of its component: roots hooked onto the smaller neighbouring
    root, then pointers jumped to their roots, until no edge joins two roots."""
    label = np.arange(n)
    while True:
        a, b = label[e[:, 0]], label[e[:, 1]]
        differ = a != b
        if not differ.any():
            return label
        a, b = a[differ], b[differ]
        np.minimum.at(label, np.maximum(a, b), np.minimum(a, b))
        while True:  # pointer jumping: every node to its root
            nxt = label[label]
            if np.array_equal(nxt, label):
                break
            label = nxt
