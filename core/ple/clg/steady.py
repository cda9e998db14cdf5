"""CLG chunks on any steady pattern (thesis §5.2): the lattice's own nodes per chunk copy.

A chunk referencing node (di, dj, dk, n) uses, in its copy at group g = (i, j, k), the pattern's
node N[g + (di, dj, dk), n] = G ∘ W^(k+dk) ∘ V^(j+dj) ∘ U^(i+di) ∘ N[0, 0, 0, n]. When U, V, W
commute this is ``M_g ∘ G⁻¹`` of the chunk at group 0 and every copy is a similar copy of one
template (``similar_copies``: the fast path of ``ple.clg.query``). Otherwise (a warped or curved
pattern) the copies are not similar, and each primitive is evaluated from the lattice's closed
forms at its own groups (``own_balls``).

Candidate copies come from the RangeFinder (§7) of an *element lattice*: the pattern's U, V, W
with one template node per (node, scale) a primitive uses and one beam-pattern per cone-beam
primitive (n_a, d_b − d_a, n_b), so that a primitive of the copy at g is the element at group
g + d_a. Its index range is the copies' range widened by the primitives' offsets, and shifted to
start at 0 (``shifted``): N[h + s] is node h of the pattern with template U^s_i ∘ N, placement
G ∘ W^s_k ∘ V^s_j and W' = V^−s_j ∘ W ∘ V^s_j (V^(j+s_j) = V^s_j ∘ V^j, and W^k ∘ V^s_j =
V^s_j ∘ W'^k). A query ball's element hits (exact ball and cone-beam tests) then name the copies
g = h − d_a it can touch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..algebra.similarity import Similarity, commute
from ..model.budget import fast_bounds
from ..model.lattice import BeamPattern, Direction, Lattice, Node, Region
from ..queries.rangefinder import lattice_hits

GROW = 1e-9  # relative growth of element radii: rounding of the shifted lattice never loses a hit


def similar_copies(lat: Lattice) -> bool:
    """Are chunk copies similar copies of the group-0 chunk, ``M_g ∘ G⁻¹`` (U, V, W commute
    pairwise; BeCOTS slabs always do)? Otherwise each copy uses the lattice's own nodes."""
    return all(commute(a, b) for a, b in ((lat.U, lat.V), (lat.U, lat.W), (lat.V, lat.W)))


def shifted(lat: Lattice, shift, counts) -> tuple[Lattice, Similarity]:
    """The pattern re-indexed from ``shift`` (3,) with ``counts`` groups per direction, and the
    similarity U^shift_i for its template: with template node T ∘ N[0, 0, 0, n], its node (h, n) is
    the pattern's node (h + shift, n) (module doc). Nodes, beams and filter are emptied."""
    si, sj, sk = (int(x) for x in shift)
    out = lat.copy()
    out.nodes, out.beams, out.filter, out.becots = [], [], None, None
    vj = lat.V ** sj
    out.u = Direction(int(counts[0]), lat.U)
    out.v = Direction(int(counts[1]), lat.V)
    out.w = Direction(int(counts[2]), lat.W if sj == 0 else vj.inverse() @ lat.W @ vj)
    out.placement = lat.placement if (sj, sk) == (0, 0) else lat.placement @ (lat.W ** sk) @ vj
    out.meta = {}
    return out, lat.U ** si


@dataclass
class ElementFinder:
    """The element lattice of a CLG's primitives and, per element (nodes first, then
    beam-patterns), the (chunk, anchor offset) of every primitive it stands for."""

    aux: Lattice
    shift: np.ndarray  # (3,): element-lattice group h is the pattern's group h + shift
    region: Region  # the copies' groups
    use_start: np.ndarray  # (E + 1,): uses of element e are rows use_start[e]:use_start[e + 1]
    use_chunk: np.ndarray  # (U,)
    use_anchor: np.ndarray  # (U, 3)
    chunks: int
    node_of: dict  # (pattern node, scale) -> element-lattice node

    def candidates(self, p: np.ndarray, r: np.ndarray):
        """Unique (query (m,), group (m, 3), chunk (m,)) of the copies whose primitives the query
        balls (p (q, 3), r (q,)) touch: element hits of the RangeFinder, each mapped to the copies
        that use the element (g = h + shift − anchor), kept where g is in the region."""
        nodes, beams, _ = lattice_hits(self.aux, p, r)
        nn = len(self.aux.nodes)
        rows = np.concatenate([nodes, beams + np.array([0, 0, 0, 0, nn])]).astype(np.int64)
        e = rows[:, 4]
        n_use = self.use_start[e + 1] - self.use_start[e]
        hit = np.repeat(np.arange(len(rows)), n_use)
        use = self.use_start[e][hit] + (np.arange(len(hit)) - np.repeat(np.cumsum(n_use) - n_use, n_use))
        g = rows[hit, 1:4] + self.shift - self.use_anchor[use]
        q, c = rows[hit, 0], self.use_chunk[use]
        lo = np.array([self.region.i0, self.region.j0, self.region.k0])
        shape = np.array(self.region.shape)
        keep = np.all((g >= lo) & (g < lo + shape), axis=1)
        q, g, c = q[keep], g[keep] - lo, c[keep]
        dims = (len(p), *(int(x) for x in shape), self.chunks)
        key = np.unique(np.ravel_multi_index((q, g[:, 0], g[:, 1], g[:, 2], c), dims))
        q, i, j, k, c = np.unravel_index(key, dims)
        return q, np.column_stack([i, j, k]) + lo, c

    def bounds(self, ends: list) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned box (lo (3,), hi (3,)) of the balls of primitive ends ``ends``, a list of
        (node, scale, offset (3,)), over every copy of the region (exact where ``fast_bounds`` is)."""
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        by_offset: dict = {}
        for n, s, d in ends:
            by_offset.setdefault(tuple(int(x) for x in d), set()).add(self.node_of[(n, s)])
        r = self.region
        for d, nodes in by_offset.items():
            a = np.array([r.i0, r.j0, r.k0]) + d - self.shift
            box = self.aux.copy()
            box.nodes = [self.aux.nodes[m] for m in sorted(nodes)]
            reg = Region(int(a[0]), int(a[0]) + r.shape[0], int(a[1]), int(a[1]) + r.shape[1],
                         int(a[2]), int(a[2]) + r.shape[2])
            b0, b1, exact = fast_bounds(box, reg)
            if not exact:
                b0, b1 = box.bounds(reg)
            lo, hi = np.minimum(lo, b0), np.maximum(hi, b1)
        return lo, hi


def element_finder(lat: Lattice, leaves: list, region: Region) -> ElementFinder:
    """The ``ElementFinder`` of the primitives ``leaves`` (one list per chunk) over the copies at
    the groups of ``region``."""
    offs = [p.a.offset for lv in leaves for p in lv] + [p.b.offset for lv in leaves for p in lv if p.b is not None]
    dmin, dmax = np.min(offs, axis=0), np.max(offs, axis=0)
    start = np.array([region.i0, region.j0, region.k0])
    shift = start + dmin
    counts = np.array(region.shape) + dmax - dmin
    aux, move = shifted(lat, shift, counts)
    node_of: dict = {}

    def node(n: int, s: float) -> int:
        if (n, s) not in node_of:
            c, rad = move.apply_balls(lat.nodes[n].center, lat.nodes[n].radius * s)
            node_of[(n, s)] = len(aux.nodes)
            aux.nodes.append(Node(c, float(rad) * (1 + GROW)))
        return node_of[(n, s)]
    beam_of: dict = {}
    uses: list = []  # (element key, chunk, anchor)
    for ci, lv in enumerate(leaves):
        for p in lv:
            a = node(p.a.n, p.sa)
            if p.b is None or (p.b.offset == p.a.offset and node(p.b.n, p.sb) == a):
                uses.append((("n", a), ci, p.a.offset))
                continue
            b = node(p.b.n, p.sb)
            d = tuple(y - x for x, y in zip(p.a.offset, p.b.offset))
            beam_of.setdefault((a, b, d), len(beam_of))
            uses.append((("b", beam_of[(a, b, d)]), ci, p.a.offset))
    aux.beams = [BeamPattern(a, b, *d) for (a, b, d) in beam_of]
    nn = len(aux.nodes)
    elem = np.array([k[1] if k[0] == "n" else nn + k[1] for k, _, _ in uses], dtype=np.int64)
    order = np.argsort(elem, kind="stable")
    counts_e = np.bincount(elem, minlength=nn + len(aux.beams))
    return ElementFinder(aux, shift, region, np.concatenate([[0], np.cumsum(counts_e)]),
                         np.array([uses[m][1] for m in order], dtype=np.int64),
                         np.array([uses[m][2] for m in order], dtype=np.int64).reshape(-1, 3), len(leaves), node_of)


def own_balls(lat: Lattice, prims: list, g: np.ndarray) -> list:
    """[(ca (m, 3), ra (m,), cb (m, 3) or None, rb (m,) or None)] of each primitive's copies at
    groups ``g`` (m, 3), from the lattice's own nodes N[g + d, n] (closed forms of ``G ∘ W^k ∘
    V^j ∘ U^i``; the group matrices of each distinct offset d computed once)."""
    g = np.asarray(g, dtype=np.int64).reshape(-1, 3)
    mats: dict = {}

    def ball(ref, s):
        d = ref.offset
        if d not in mats:
            h = g + np.asarray(d)
            m = lat.group_matrices(h[:, 0], h[:, 1], h[:, 2])
            mats[d] = (m[:, :3, :3], m[:, :3, 3], lat.group_factors(h[:, 0], h[:, 1], h[:, 2]))
        lin, move, f = mats[d]
        c = lin @ lat.nodes[ref.n].center + move
        r = f * (lat.nodes[ref.n].radius * s)
        if lat.radius_field is not None:
            r = r * lat.radius_field.factors(c)
        return c, r
    out = []
    for p in prims:
        ca, ra = ball(p.a, p.sa)
        cb, rb = (None, None) if p.b is None else ball(p.b, p.sb)
        out.append((ca, ra, cb, rb))
    return out
