"""Unclean pairs and gaps between non-incident elements (CHoCC paper §1: a lattice is *clean* when
its beams are disjoint unless they are incident on the same ball; we also flag a ball overlapping a
beam or a ball it is not incident on, which breaks the hub decomposition of ``measure`` and the
meshes of ``meshing`` alike).

Two elements are *incident* when they share a ball (a beam and its end balls, two beams with a
common end, two balls joined by a beam). A non-incident pair is *unclean* when the elements overlap
by more than ``CLEAN_TOL`` of their size (touching is clean); its *gap* is their distance (0 when
they meet). Pairs are found without all-pairs work:

- ``steady`` path (an unfiltered steady lattice, not BeCOTS): overlap is invariant under
  similarities, so along every direction whose similarity commutes with the later ones (W always,
  §6.1.4; V, U as in ``similar_axes``) a pair whose lower element lies past the first ``reach``
  indices is a similar copy of a pair anchored at index ``reach``. Only the elements of the anchor
  groups (the base slab k ≤ reach for a general steady lattice; one corner block of groups when U,
  V and W are all similar, as for regular lattices) are queried, with the RangeFinder. Each
  unordered pair class is taken from the element lower in the first similar direction where the
  two differ, so its partner lies at or above the anchor there; in the later similar directions
  it may lie below index 0, so the lattice is extended by its counts on the lower side of those
  only (never along the first: a full turn of a rotation row is not repeated, and the
  RangeFinder's ranges stay one turn wide). Each pair class is counted over the index interval
  where both of its elements exist;
- ``explicit`` path (filtered lattices, regions, BeCOTS slabs): the evaluated (kept) elements, their
  bounding balls hashed in a uniform grid, candidate pairs from neighbouring cells only.
"""

from __future__ import annotations

import math

import numpy as np

from ..algebra.elements import beam_beam_gap, beam_distance, enclosing_ball, segment_closest, segment_distance
from ..algebra.similarity import commute
from ..algebra.vectors import runs
from ..errors import PleError, echo
from ..model.lattice import Evaluation, Lattice
from .rangefinder import lattice_hits

CLEAN_TOL = 1e-9  # overlap depth, relative to the larger radius of the pair, below which elements only touch
WORST = 10  # worst offenders listed
MAX_ANCHOR_FRACTION = 0.02  # "auto" takes the steady path when the anchors are at most this share of all groups
MAX_EXPLICIT = 2_000_000  # ... or when more elements than this would be evaluated
PAIR_CHUNK = 1 << 18  # candidate pairs per vectorized block
GRID_ENTRIES_PER_ELEMENT = 64  # grid cells listed per element (elements of similar sizes cover at most 8)
MIN_GRID_ENTRIES = 1 << 24  # ... and at least this many (16 B each)
ROW_CHUNK = 1 << 16  # boxes whose grid cells are listed at once (their entries' temporaries)
QUERY_CHUNK = 1 << 10  # anchor blocks per RangeFinder batch
ANCHOR_BLOCK = 4  # anchor groups per block side: one RangeFinder query per block
KINDS = ("ball_ball", "ball_beam", "beam_beam")
PAIRS_PER_ELEMENT = 256  # default limit of candidate pairs per element (the presets, clean, have 10–76)
MIN_PAIR_LIMIT = 10_000_000  # ... and at least this many (at most about a minute of exact tests)


def similar_axes(lat: Lattice) -> tuple[bool, bool, bool]:
    """Directions along which the rows are similar copies of each other (hubs, element pairs): W
    always; V if V and W commute; U if U commutes with V and W (or those are single, §3.6–3.7)."""
    act = [c > 1 for c in lat.counts]
    vw = not (act[1] and act[2]) or commute(lat.V, lat.W)
    u = all(not (act[0] and act[x]) or commute(lat.U, s) for x, s in ((1, lat.V), (2, lat.W)))
    return u, vw, True


def reach(lat: Lattice) -> list[int]:
    """Largest beam-pattern offset per direction."""
    return [max([abs(b.offset[d]) for b in lat.beams], default=0) for d in range(3)]


# ----- exact pair tests ------------------------------------------------------------------------------
def pair_gaps(kind_a, ca, ra, ea, kind_b, cb, rb, eb, margin: float = math.inf):
    """Gap (distance, 0 where they meet), overlap flag and overlap depth of element pairs. Element
    data: kind 0 a ball (centre c, radius r), kind 1 a beam (c, r: start ball; e = (end centre, end
    radius)). Beam pairs whose axes lie farther apart than their radii plus ``margin`` get a lower
    bound of their gap (axis distance minus the largest radii) instead of the exact value."""
    n = len(kind_a)
    gap = np.empty(n)
    over = np.zeros(n, bool)
    depth = np.zeros(n)
    scale = np.maximum(np.maximum(ra, rb), np.maximum(ea[1], eb[1]))
    tol = CLEAN_TOL * scale
    bb = (kind_a == 0) & (kind_b == 0)
    if bb.any():
        d = np.linalg.norm(ca[bb] - cb[bb], axis=1) - ra[bb] - rb[bb]
        gap[bb], over[bb], depth[bb] = np.maximum(d, 0), d < -tol[bb], -d
    for ball_first in (True, False):
        sel = (kind_a == 0) & (kind_b == 1) if ball_first else (kind_a == 1) & (kind_b == 0)
        if not sel.any():
            continue
        (c, r), (a, r1, (b, r2)) = ((ca, ra), (cb, rb, eb)) if ball_first else ((cb, rb), (ca, ra, ea))
        d = beam_distance(c[sel], a[sel], r1[sel], b[sel], r2[sel]) - r[sel]
        gap[sel], over[sel], depth[sel] = np.maximum(d, 0), d < -tol[sel], -d
    ee = (kind_a == 1) & (kind_b == 1)
    if ee.any():
        bound = (segment_distance(ca[ee], ea[0][ee], cb[ee], eb[0][ee]) - np.maximum(ra[ee], ea[1][ee])
                 - np.maximum(rb[ee], eb[1][ee]))
        near = np.nonzero(ee)[0][bound <= margin]
        gap[ee] = bound
        ee = np.zeros_like(ee)
        ee[near] = True
    if ee.any():
        rows = np.nonzero(ee)[0]
        args = (ca[rows], ra[rows], ea[0][rows], ea[1][rows], cb[rows], rb[rows], eb[0][rows], eb[1][rows])
        # special case: the balls of both beams at their axes' closest points overlap by more than
        # the tolerance, so the beams overlap (gap 0) without two golden-section searches per pair
        # (the common case where elements overlap many others)
        g = np.zeros(len(rows))
        o = _surely_overlapping(*args, tol[rows])
        ex = np.nonzero(~o)[0]
        if len(ex):
            sub = [x[ex] for x in args]
            g[ex] = beam_beam_gap(*sub)
            meet = ex[g[ex] <= 0]
            if len(meet):  # overlap or touch: the beams shrunk by the tolerance still meet when they overlap
                shrunk = [x[meet] - (tol[rows][meet] if i % 2 else 0) for i, x in enumerate(args)]
                o[meet] = beam_beam_gap(*shrunk) <= 0
        gap[rows], over[rows] = g, o
        meet = g <= 0
        if meet.any():  # depth estimate: how far the first beam's axis balls reach into the second beam
            dep = np.zeros(len(rows))
            t = np.linspace(0, 1, 17)[:, None]
            p = args[0][meet][None] + t[..., None] * (args[2][meet] - args[0][meet])[None]
            rr = args[1][meet][None] + t * (args[3][meet] - args[1][meet])[None]
            dep[meet] = np.max(rr - beam_distance(p, args[4][meet][None], args[5][meet][None], args[6][meet][None],
                                                  args[7][meet][None]), axis=0)
            depth[rows] = dep
    depth = np.where(over, depth, 0.0)
    return gap, over, depth


def _surely_overlapping(a1, ra1, b1, rb1, a2, ra2, b2, rb2, tol) -> np.ndarray:
    """Cone-beam pairs that overlap by more than ``tol``, certified by one ball of each: a cone-beam
    holds the ball (a + s (b − a), ra + s (rb − ra)) for every s in [0, 1], and at the closest points
    of the two axes these balls, shrunk by ``tol``, intersect. False means only "not certified"."""
    s, t = segment_closest(a1, b1, a2, b2)
    p = a1 + s[:, None] * (b1 - a1)
    q = a2 + t[:, None] * (b2 - a2)
    r = ra1 + s * (rb1 - ra1) + ra2 + t * (rb2 - ra2)
    return np.linalg.norm(p - q, axis=1) < r - 3 * tol


# ----- explicit elements --------------------------------------------------------------------------------
def _explicit(ev: Evaluation, margin: float, first: bool = False, max_pairs: float | None = None) -> dict:
    nn, nb = len(ev.radius), len(ev.beam_nodes)
    ends = np.concatenate([np.repeat(np.arange(nn)[:, None], 2, axis=1), ev.beam_nodes]).astype(np.int64)
    kinds = np.concatenate([np.zeros(nn, np.int64), np.ones(nb, np.int64)])
    labels = np.concatenate([np.concatenate([ev.node_index, ev.beam_index]), kinds[:, None]], axis=1)
    ca, ra, cb, rb = ev.center[ends[:, 0]], ev.radius[ends[:, 0]], ev.center[ends[:, 1]], ev.radius[ends[:, 1]]
    box_lo = np.minimum(ca - ra[:, None], cb - rb[:, None])
    box_hi = np.maximum(ca + ra[:, None], cb + rb[:, None])
    if not first:  # the quick look stops at its first unclean block: bounded without an estimate
        check_pairs(candidate_pairs(box_lo, box_hi, margin), nn + nb, max_pairs)
    result = _Collector(margin)
    for i, j in non_incident_pairs(ends, kinds, box_lo, box_hi, ev.beam_nodes, margin):
        ia, ib = ends[i], ends[j]
        ea = (ev.center[ia[:, 1]], ev.radius[ia[:, 1]])
        eb = (ev.center[ib[:, 1]], ev.radius[ib[:, 1]])
        gap, over, depth = pair_gaps(kinds[i], ev.center[ia[:, 0]], ev.radius[ia[:, 0]], ea,
                                     kinds[j], ev.center[ib[:, 0]], ev.radius[ib[:, 0]], eb, margin)
        result.add(kinds[i], kinds[j], gap, over, depth, labels[i], labels[j], np.ones(len(i), np.int64), gap)
        if first and over.any():  # the question was only whether one exists (everything may overlap everything)
            break
    out = result.report()
    out["path"] = "explicit"
    out["elements"] = int(nn + nb)
    return out


def incident_keys(ends: np.ndarray, beam_nodes: np.ndarray) -> tuple[int, np.ndarray]:
    """(nn, sorted keys a · nn + b of every beam's two end nodes, both ways): what
    ``non_incident_pairs`` looks two balls up in; computed once for a search made in blocks."""
    bn = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    nn = max(int(ends.max()) if len(ends) else -1, int(bn.max()) if len(bn) else -1) + 1
    return nn, np.sort(np.concatenate([bn[:, 0] * nn + bn[:, 1], bn[:, 1] * nn + bn[:, 0]]))


def non_incident_pairs(ends: np.ndarray, kinds: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray,
                       beam_nodes: np.ndarray, margin: float = 0.0, split: int | None = None, keys=None):
    """Pairs (i, j), i < j, of explicit elements whose boxes (grown by margin / 2, ``grid_pairs``)
    meet and which are not incident: they share no ball, and are not two balls joined by a beam.
    ``ends`` (E, 2): node rows of each element (a ball: (n, n)); ``kinds`` (E,): 0 ball, 1 beam;
    ``beam_nodes`` (M, 2) the beams' node rows. Yielded in blocks of index arrays. The one
    candidate search of unclean elements: ``unclean_pairs`` tests the pairs exactly, the
    tessellation (``meshing.unclean``) with its conservative junction spheres. ``split``: only
    pairs i < split <= j (``grid_pairs``). ``keys``: ``incident_keys`` of all the elements, when
    these are a block of them."""
    nn, edge_keys = incident_keys(ends, beam_nodes) if keys is None else keys
    for i, j in grid_pairs(box_lo, box_hi, margin, split):
        ia, ib = ends[i], ends[j]
        shared = (ia[:, :1] == ib).any(axis=1) | (ia[:, 1:] == ib).any(axis=1)
        both_balls = (kinds[i] == 0) & (kinds[j] == 0)
        if both_balls.any() and len(edge_keys):
            key = ia[:, 0] * nn + ib[:, 0]
            pos = np.minimum(np.searchsorted(edge_keys, key), len(edge_keys) - 1)
            shared |= both_balls & (edge_keys[pos] == key)
        if (~shared).any():
            yield i[~shared], j[~shared]


def grid_pairs(box_lo: np.ndarray, box_hi: np.ndarray, margin: float, split: int | None = None):
    """Index pairs (i < j) of axis-aligned boxes closer than ``margin`` (each grown by margin / 2);
    with ``split``, only pairs i < split <= j (boxes of a first set against a second). Each box
    (of the first set) is entered in every cell of a uniform grid (cell: the median box diagonal)
    it overlaps; a pair is reported by the one cell holding the larger of the two lower corners
    (no duplicates). Yielded in blocks formed from about PAIR_CHUNK candidate pairs."""
    n = len(box_lo)
    if n < 2 or (split is not None and not 0 < split < n):
        return
    blo, bhi, lo, span, dims = _grid(box_lo, box_hi, margin)
    first = 0 if split is None else split  # rows looked up in the table of rows [0, split or n)
    parts = [_cell_entries(lo, span, dims, np.arange(a, min(a + ROW_CHUNK, split or n)))
             for a in range(0, split or n, ROW_CHUNK)]  # (chunks of rows: their cells' temporaries stay small)
    key_all, owner_all = (np.concatenate(x) for x in zip(*parts))
    del parts
    sort = np.argsort(key_all, kind="stable")
    table = (key_all[sort], owner_all[sort])
    del key_all, owner_all, sort
    # blocks of rows forming about PAIR_CHUNK candidates each: a row forms one per entry of every
    # cell it covers (where elements overlap many others, thousands a row)
    starts = np.flatnonzero(np.diff(table[0], prepend=table[0][:1] - 1))  # the table is sorted: runs are cells
    cells, counts = table[0][starts], np.diff(np.append(starts, len(table[0])))
    formed = np.zeros(n - first)
    for a in range(first, n, ROW_CHUNK):
        key_q, owner_q = _cell_entries(lo, span, dims, np.arange(a, min(a + ROW_CHUNK, n)))
        pos = np.minimum(np.searchsorted(cells, key_q), max(len(cells) - 1, 0))
        per = np.where(cells[pos] == key_q, counts[pos], 0) + 1 if len(cells) else np.ones(len(key_q))
        formed[a - first:a - first + ROW_CHUNK] = np.bincount(owner_q - a, weights=per, minlength=min(ROW_CHUNK, n - a))
    cum = np.cumsum(formed)
    bounds = first + np.searchsorted(cum, np.arange(0, cum[-1], PAIR_CHUNK), "right")
    edges = np.unique(np.concatenate([[first], bounds, [n]]))
    for start, stop in zip(edges[:-1], edges[1:]):
        key, owner = _cell_entries(lo, span, dims, np.arange(start, stop))
        a, b = np.searchsorted(table[0], key, "left"), np.searchsorted(table[0], key, "right")
        cnt = b - a
        j = np.repeat(owner, cnt)
        cell = np.repeat(key, cnt)
        i = table[1][runs(a, cnt)]
        keep = i < j
        i, j, cell = i[keep], j[keep], cell[keep]
        corner = np.maximum(lo[i], lo[j])  # the one cell that reports the pair
        keep = ((corner[:, 0] * dims[1] + corner[:, 1]) * dims[2] + corner[:, 2]) == cell
        i, j = i[keep], j[keep]
        hit = (blo[i] <= bhi[j]) & (blo[j] <= bhi[i])
        near = hit[:, 0] & hit[:, 1] & hit[:, 2]
        if near.any():
            yield i[near], j[near]


def _grid(box_lo, box_hi, margin: float):
    """The uniform grid of ``grid_pairs``: boxes grown by margin / 2 (blo, bhi (E, 3)), the first
    cell (E, 3) and the number of cells (E, 3) each covers, and the grid's cells per axis (3,).
    Refused (``PairLimitError``) when the boxes would make more than ``GRID_ENTRIES_PER_ELEMENT``
    entries per element (at least ``MIN_GRID_ENTRIES``) or more cells than int64 keys hold:
    elements of sizes far apart (a scaling's powers), where cells of the median size are tiny
    beside the largest boxes. Counted as floats first, so nothing overflows."""
    blo, bhi = box_lo - margin / 2, box_hi + margin / 2
    size = np.max(bhi - blo, axis=1)
    h = max(float(np.median(size)), 1e-12)
    origin = blo.min(axis=0)
    lo_f, hi_f = np.floor((blo - origin) / h), np.floor((bhi - origin) / h)
    entries = float(np.sum(np.prod(hi_f - lo_f + 1, axis=1)))
    limit = max(MIN_GRID_ENTRIES, GRID_ENTRIES_PER_ELEMENT * len(blo))
    if not (entries <= limit and float(np.prod(hi_f.max(axis=0) + 1)) < 2.0**62):
        raise PairLimitError(f"the clean check's grid would list its {len(blo):,} elements in {entries:.3g} cells "
                             f"(more than {limit:.3g}): their sizes range from {size.min():.3g} to {size.max():.3g}, "
                             "too far apart for one grid; check a smaller --region")
    lo, hi = lo_f.astype(np.int64), hi_f.astype(np.int64)
    return blo, bhi, lo, hi - lo + 1, hi.max(axis=0) + 1


def candidate_pairs(box_lo: np.ndarray, box_hi: np.ndarray, margin: float, split: int | None = None) -> int:
    """How many candidate pairs ``grid_pairs`` will enumerate for these boxes (E, 3), counted from
    its grid's cells alone before any pair is formed: in each cell, every two of its boxes (with
    ``split``, every box of the first set with every box of the second). The work of the clean
    check grows with it; an upper bound of the pairs it tests exactly."""
    n = len(box_lo)
    if n < 2 or (split is not None and not 0 < split < n):
        return 0
    _, _, lo, span, dims = _grid(box_lo, box_hi, margin)
    key, owner = _cell_entries(lo, span, dims, np.arange(n))
    if split is None:
        c = np.unique(key, return_counts=True)[1].astype(np.float64)
        return int(np.sum(c * (c - 1) / 2))
    first = owner < split
    cells, inverse = np.unique(key, return_inverse=True)
    a = np.bincount(inverse.reshape(-1)[first], minlength=len(cells)).astype(np.float64)
    b = np.bincount(inverse.reshape(-1)[~first], minlength=len(cells)).astype(np.float64)
    return int(a @ b)


class PairLimitError(PleError):
    """A clean check refused for its candidate pairs (``check_pairs``)."""


def check_pairs(pairs: float, elements: int, max_pairs: float | None) -> None:
    """Refuse a clean check whose candidate pairs exceed ``max_pairs`` (None: the default, at
    least ``MIN_PAIR_LIMIT`` and ``PAIRS_PER_ELEMENT`` per element). Elements that all overlap
    each other make their pairs grow with the square of their number."""
    limit = max(MIN_PAIR_LIMIT, PAIRS_PER_ELEMENT * elements) if max_pairs is None else max_pairs
    if pairs > limit:
        raise PairLimitError(f"the clean check would test about {pairs:.3g} candidate pairs of elements "
                       f"({pairs / max(elements, 1):.3g} per element of {elements:,}; estimated before testing), "
                       f"more than the limit {limit:.3g}: its elements overlap many others; check a smaller "
                       "--region, or raise the limit with --max-pairs")


def _cell_entries(lo, span, dims, rows):
    """(cell key, element) for every grid cell each element's box covers."""
    sp = span[rows]
    per = sp[:, 0] * sp[:, 1] * sp[:, 2]
    base = (lo[rows, 0] * dims[1] + lo[rows, 1]) * dims[2] + lo[rows, 2]  # the first cell's key
    if (per == 1).all():  # every box in one cell
        return base, rows
    k = np.repeat(np.arange(len(rows)), per)
    local = runs(np.zeros(len(rows), np.int64), per)
    sz, sy = sp[k, 2], sp[k, 1]
    cz, t = local % sz, local // sz
    return base[k] + ((t // sy) * dims[1] + t % sy) * dims[2] + cz, rows[k]


class _Collector:
    """Counts unclean pairs per kind, keeps the worst offenders and the smallest gap."""

    def __init__(self, margin: float) -> None:
        self.margin = margin
        self.counts = dict.fromkeys(KINDS, 0)
        self.worst: list[dict] = []
        self.min_gap = (math.inf, None)

    def add(self, ka, kb, gap, over, depth, ia, ib, count, min_gap):
        kind = ka + kb  # 0 ball-ball, 1 ball-beam, 2 beam-beam
        for k, name in enumerate(KINDS):
            self.counts[name] += int(count[over & (kind == k)].sum())
        bad = np.nonzero(over)[0]
        bad = bad[np.argsort(-depth[bad])[:WORST]]
        for t in bad:
            self.worst.append({"kind": KINDS[kind[t]], "depth": float(depth[t]), "count": int(count[t]),
                               "a": _label(ia[t]), "b": _label(ib[t])})
        self.worst = sorted(self.worst, key=lambda w: -w["depth"])[:WORST]
        ok = np.nonzero(~over & (min_gap <= self.margin))[0]
        if len(ok):
            t = ok[np.argmin(min_gap[ok])]
            if min_gap[t] < self.min_gap[0]:
                self.min_gap = (float(min_gap[t]), {"a": _label(ia[t]), "b": _label(ib[t])})

    def report(self) -> dict:
        total = sum(self.counts.values())
        return {"clean": total == 0, "unclean_pairs": total, "pairs": dict(self.counts), "worst": self.worst,
                "min_gap": None if self.min_gap[1] is None else self.min_gap[0], "min_gap_pair": self.min_gap[1],
                "gap_search": self.margin}


def _label(row) -> dict:
    """{"ball": [i, j, k, n]} or {"beam": [i, j, k, pattern]} from (i, j, k, x, kind)."""
    return {("ball", "beam")[int(row[4])]: [int(x) for x in row[:4]]}


# ----- steady lattices: anchors and similar copies --------------------------------------------------------------
def _extended(lat: Lattice, ext: np.ndarray) -> Lattice:
    """The lattice extended by ``ext[d]`` groups below index 0 of every direction d (its group
    (i, j, k) is the extension's (i + ext_u, j + ext_v, k + ext_w))."""
    out = lat.with_counts(*(int(c + e) for c, e in zip(lat.counts, ext)))
    shift = lat.placement
    for step, e in zip((lat.W, lat.V, lat.U), ext[::-1]):
        if e:
            shift = shift @ (step ** (-int(e)))
    out.set_placement(shift)
    out.set_filter(None)
    return out


def _exist(lat: Lattice, kind: np.ndarray, x: np.ndarray):
    """Per element (ball n or beam pattern p): the index interval [lo, hi) (…, 3) of groups where it exists."""
    counts = np.array(lat.counts)
    off = np.array([b.offset for b in lat.beams], np.int64).reshape(-1, 3)
    o = np.where(kind[:, None] == 1, off[np.where(kind == 1, x, 0)] if len(off) else 0, 0)
    return np.maximum(0, -o), counts - np.maximum(0, o)


def _elements_at(lat: Lattice, kind, idx):
    """Start centre, start radius, (end centre, end radius) of elements (kind, (i, j, k, x)); balls
    repeat themselves as the end."""
    pats = np.array([(b.n1, b.n2, *b.offset) for b in lat.beams], np.int64).reshape(-1, 5)
    p = pats[np.where(kind == 1, idx[:, 3], 0)] if len(pats) else np.zeros((len(kind), 5), np.int64)
    start_n = np.where(kind == 1, p[:, 0], idx[:, 3])
    end = idx[:, :3] + np.where(kind[:, None] == 1, p[:, 2:], 0)
    end_n = np.where(kind == 1, p[:, 1], idx[:, 3])
    ca, ra = lat.node_balls(np.concatenate([idx[:, :3], start_n[:, None]], axis=1))
    cb, rb = lat.node_balls(np.concatenate([end, end_n[:, None]], axis=1))
    nodes = (np.concatenate([idx[:, :3], start_n[:, None]], axis=1), np.concatenate([end, end_n[:, None]], axis=1))
    return ca, ra, (cb, rb), nodes


def _steady(lat: Lattice, margin: float, force: bool = False, max_pairs: float | None = None):
    sim = similar_axes(lat)
    rch = reach(lat)
    counts = np.array(lat.counts)
    rep = np.array([r if s and c > r + 1 else -1 for r, s, c in zip(rch, sim, counts)])  # -1: no similar copies
    anchors = [np.arange(min(c, r + 1)) if p >= 0 else np.arange(c) for c, r, p in zip(counts, rch, rep)]
    n_anchor = math.prod(len(a) for a in anchors)
    elements = lat.node_count() + lat.beam_count()
    if not force and n_anchor > MAX_ANCHOR_FRACTION * lat.groups and elements <= MAX_EXPLICIT:
        return None
    later = (rep >= 0) & (np.cumsum(rep >= 0) > 1)  # similar directions after the first
    ext = np.where(later, counts, 0)
    big = _extended(lat, ext)
    # the smallest factor a moved pair can have, relative to its anchor: gaps are searched that much wider
    shrink = 1.0
    for d, step in enumerate((lat.U, lat.V, lat.W)):
        if rep[d] >= 0:
            shrink *= min(1.0, step.factor ** (counts[d] - 1 - rep[d]))
    search = margin / shrink
    g = np.stack(np.meshgrid(*anchors, indexing="ij"), axis=-1).reshape(-1, 3)
    nn, nb = len(lat.nodes), len(lat.beams)
    gi = np.repeat(g, nn + nb, axis=0)
    x = np.tile(np.concatenate([np.arange(nn), np.arange(nb)]), len(g))
    kind = np.tile(np.concatenate([np.zeros(nn, np.int64), np.ones(nb, np.int64)]), len(g))
    lo, hi = _exist(lat, kind, x)
    alive = np.all((gi >= lo) & (gi < hi), axis=1)
    kind, idx = kind[alive], np.concatenate([gi, x[:, None]], axis=1)[alive]
    ca, ra, (cb, rb), nodes = _elements_at(lat, kind, idx)
    qc, qr = enclosing_ball(ca, ra, cb, rb)
    result = _Collector(margin)
    queries = 0
    # anchor elements in blocks of ANCHOR_BLOCK³ groups: one RangeFinder query per block (the ball
    # around its elements' balls, grown by the gap search) finds every partner of its elements
    _, block = np.unique(idx[:, :3] // ANCHOR_BLOCK, axis=0, return_inverse=True)
    block = block.reshape(-1)
    n_blocks = int(block.max()) + 1 if len(block) else 0
    lo_box = np.full((n_blocks, 3), np.inf)
    hi_box = np.full((n_blocks, 3), -np.inf)
    np.minimum.at(lo_box, block, qc - qr[:, None])
    np.maximum.at(hi_box, block, qc + qr[:, None])
    bc = (lo_box + hi_box) / 2
    br = np.linalg.norm(hi_box - lo_box, axis=1) / 2 + search
    found = []
    for s in range(0, n_blocks, QUERY_CHUNK):
        node_hits, beam_hits, _ = lattice_hits(big, bc[s:s + QUERY_CHUNK], br[s:s + QUERY_CHUNK])
        found += [np.concatenate([np.zeros((len(node_hits), 1), np.int64), node_hits[:, 1:]], axis=1),
                  np.concatenate([np.ones((len(beam_hits), 1), np.int64), beam_hits[:, 1:]], axis=1)]
        queries += min(QUERY_CHUNK, n_blocks - s)
        # the hits held (each paired with anchor elements later) are bounded as they arrive
        check_pairs(sum(map(len, found)), elements, max_pairs)
    hits = np.unique(np.concatenate(found), axis=0) if found else np.zeros((0, 5), np.int64)
    yk = hits[:, 0]
    yi = hits[:, 1:] - np.concatenate([ext, [0]])  # back to the lattice's own indices (possibly outside it)
    ydata = _elements_at(lat, yk, yi)
    hc, hr = enclosing_ball(ydata[0], ydata[1], *ydata[2])
    # candidate (anchor, partner) pairs: balls within the gap search (every partner of an anchor
    # is among the hits of its block's query)
    xdata = (ca, ra, (cb, rb), nodes)
    cen, rad = np.concatenate([qc, hc]), np.concatenate([qr, hr])
    n_anchor_el = len(qc)
    check_pairs(candidate_pairs(cen - rad[:, None], cen + rad[:, None], search, split=n_anchor_el), elements,
                max_pairs)
    for qa, hb in grid_pairs(cen - rad[:, None], cen + rad[:, None], search, split=n_anchor_el):
        hb = hb - n_anchor_el
        if len(qa):
            _steady_pairs(lat, result, rep, counts, search, kind[qa], idx[qa], _rows(xdata, qa), yk[hb], yi[hb],
                          _rows(ydata, hb))
    out = result.report()
    out["path"] = "steady (" + "".join(n for n, p in zip("UVW", rep) if p >= 0) + " similar)"
    out["queries"] = queries
    out["anchor_groups"] = int(n_anchor)
    return out


def _rows(data, r):
    """Rows ``r`` of element data (start centre, start radius, (end centre, end radius), (start node, end node))."""
    return data[0][r], data[1][r], (data[2][0][r], data[2][1][r]), (data[3][0][r], data[3][1][r])


def _steady_pairs(lat, result, rep, counts, search, xk, xi, xdata, yk, yi, ydata):
    """Exact tests and occurrence counts of ordered pairs (anchor X, partner Y); element data
    as ``_elements_at`` gives it. Only one orientation of each unordered pair is tested."""
    one = _first_orientation(rep, counts, xk, xi, yk, yi)
    xk, xi, yk, yi = xk[one], xi[one], yk[one], yi[one]
    xdata, ydata = (_rows(xdata, one), _rows(ydata, one))
    same = (xk == yk) & np.all(xi == yi, axis=1)
    xa, xr, xe_, (xs, xe) = xdata
    ya, yr, (yc, yrr), ynodes = ydata
    # incidence: shared node (group and node id), or two balls joined by a beam
    xn = np.stack([xs, xe], axis=1)  # (P, 2, 4)
    yn = np.stack(ynodes, axis=1)
    shared = np.any(np.all(xn[:, :, None, :] == yn[:, None, :, :], axis=3), axis=(1, 2))
    balls = (xk == 0) & (yk == 0)
    if balls.any():
        for b in lat.beams:
            for n1, n2, sgn in ((b.n1, b.n2, 1), (b.n2, b.n1, -1)):
                joined = balls & (xi[:, 3] == n1) & (yi[:, 3] == n2) & np.all(yi[:, :3] - xi[:, :3] == sgn * np.array(
                    b.offset), axis=1)
                shared |= joined
    keep = ~same & ~shared
    if not keep.any():
        return
    xk, xi, yk, yi = xk[keep], xi[keep], yk[keep], yi[keep]
    xa, xr, xe_ = xa[keep], xr[keep], (xe_[0][keep], xe_[1][keep])
    ya, yr, ye = ya[keep], yr[keep], (yc[keep], yrr[keep])
    gap, over, depth = pair_gaps(xk, xa, xr, xe_, yk, ya, yr, ye, search)
    # occurrences: groups g (X at g, Y at g + δ) with both existing; similar directions move the anchor
    delta = yi[:, :3] - xi[:, :3]
    xlo, xhi = _exist(lat, xk, xi[:, 3])
    ylo, yhi = _exist(lat, yk, yi[:, 3])
    lo = np.maximum(xlo, ylo - delta)
    hi = np.minimum(xhi, yhi - delta)
    moving = (rep >= 0)[None] & (xi[:, :3] == rep[None])
    lo = np.where(moving, np.maximum(lo, xi[:, :3]), np.maximum(lo, xi[:, :3]))
    hi = np.where(moving, hi, np.minimum(hi, xi[:, :3] + 1))
    count = np.prod(np.maximum(hi - lo, 0), axis=1)
    # the smallest gap over the occurrences: the factor changes monotonically along each direction
    factors = np.array([lat.U.factor, lat.V.factor, lat.W.factor])
    last = np.maximum(hi - 1, lo)
    corner = np.where(factors[None] < 1, last, lo)
    scale = np.prod(factors[None] ** (corner - xi[:, :3]), axis=1)
    ok = count > 0
    ia = np.concatenate([np.where(ok[:, None], np.concatenate([lo, xi[:, 3:]], axis=1), xi), xk[:, None]], axis=1)
    ib = np.concatenate([ia[:, :3] + delta, yi[:, 3:], yk[:, None]], axis=1)
    keep = ok
    result.add(xk[keep], yk[keep], gap[keep], over[keep], depth[keep], ia[keep], ib[keep], count[keep],
               gap[keep] * scale[keep])


def _first_orientation(rep, counts, xk, xi, yk, yi) -> np.ndarray:
    """Which ordered pairs (X, Y) are the one orientation kept of their unordered pair: each is met
    from both elements when neither lies lower along a similar direction (then kinds, node ids
    and the offset decide); otherwise only from the element lower in the first similar direction
    where they differ (the only one the queries are sure to meet)."""
    delta = yi[:, :3] - xi[:, :3]
    big = 3 * int(counts.max()) + 1
    d_key = (delta[:, 0] * big + delta[:, 1]) * big + delta[:, 2]
    first = (xk < yk) | ((xk == yk) & ((xi[:, 3] < yi[:, 3]) | ((xi[:, 3] == yi[:, 3]) & (d_key > 0))))
    sim_delta = np.where((rep >= 0)[None], delta, 0)
    lead = np.argmax(sim_delta != 0, axis=1)
    lead_delta = sim_delta[np.arange(len(delta)), lead]
    return np.where(lead_delta != 0, lead_delta > 0, first)


# ----- public API -----------------------------------------------------------------------------------------
def unclean_pairs(lat: Lattice, ev: Evaluation | None = None, margin: float = 0.0, path: str = "auto",
                  first: bool = False, max_pairs: float | None = None) -> dict:
    """Unclean pairs of a lattice, or of the elements ``ev`` (an evaluation of it: a region, or the
    kept part of a filtered lattice): {"clean", "unclean_pairs", "pairs" per kind, "worst" offenders
    (kind, depth, count of similar copies, both elements as {"ball"|"beam": [i, j, k, n|pattern]}),
    "min_gap" among non-incident pairs closer than ``margin`` (None if none), "min_gap_pair",
    "path"}. Without ``ev``: the whole unfiltered program (``path`` "auto" takes the steady path
    when it applies, "explicit" evaluates the lattice). ``first``: explicit elements stop at the
    first block of candidate pairs holding an unclean pair (only "clean" is then complete: the
    quick answer, bounded in time and memory when everything overlaps everything). Otherwise the
    candidate pairs are counted before they are tested (``candidate_pairs``) and more than
    ``max_pairs`` (None: ``check_pairs``'s default, which grows with the elements) is a PleError."""
    lat.validate()
    if path not in ("auto", "steady", "explicit"):
        raise PleError(f"unclean-pair path {echo(path)}: expected auto, steady or explicit")
    if ev is None and path != "explicit" and lat.becots is None:
        out = _steady(lat, float(margin), force=path == "steady", max_pairs=max_pairs)
        if out is not None:
            return out
    if ev is None:
        ev = lat.evaluate()
    return _explicit(ev, float(margin), first, max_pairs)


def is_clean(lat: Lattice, ev: Evaluation | None = None) -> bool:
    """Whether no two non-incident elements overlap (see ``unclean_pairs``)."""
    return unclean_pairs(lat, ev)["clean"]
