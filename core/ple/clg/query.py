"""PMC and local distance bounds of a CLG (thesis §5.5, §5.7, §10.2), visiting only the chunk copies
a query can touch.

Similar copies (U, V, W commute, ``ple.clg.steady.similar_copies``): every primitive of every
template chunk gets a bounding ball, and these balls become the template node-group of an
auxiliary lattice with the pattern's U, V, W, counts, placement and BeCOTS description. The copy of
a chunk at group g is ``M_g ∘ G⁻¹`` of the chunk at group 0 (``M_g = G ∘ W^k ∘ V^j ∘ U^i``), so the
auxiliary node (g, m) bounds primitive m in the copy at g. A query ball (P, R) asks the auxiliary
lattice which groups it touches — the BeCOTS RangeFinder (§8) in O(1) per query on BeCOTS slabs,
the RangeFinder paths (§7) on steady lattices — after a box bound and the conical shell have
rejected far points. Only those chunk copies are evaluated.

Any other steady pattern: each copy uses the lattice's own nodes N[g + d, n], and the candidates
come from the RangeFinder of the element lattice of ``ple.clg.steady`` (the pattern's U, V, W with
the primitives as its nodes and beam-patterns), after the box bound.

Values follow the CSG distance rules of §5.7 (union: min, intersection: max, difference: max(a, −b))
on exact signed distances of balls and cone-beams, clipped to [−R, R]: leaves farther than R are
known only to be ≥ R, and clipping commutes with min, max and negation, so the clipped value is
exact. With R = 0 the sign is exact (PMC: inside iff value ≤ 0). A primitive X with a replacing
CLG L has value max(d_X, d_L), L evaluated only where X may contain the point (L ⊂ X, §10.2).
"""

from __future__ import annotations

import numpy as np

from ..algebra.elements import beam_distance, enclosing_ball
from ..algebra.vectors import cross
from ..errors import PleError
from ..model.budget import fast_bounds
from ..model.lattice import Node
from ..queries import biq
from ..queries.rangefinder import lattice_hits
from .bound import conical_shell
from .model import CLG, ChunkRef, Op, Prim, leaves, positive_leaves
from .rays import next_crossing, ray_ball_interval, ray_beam_interval
from .steady import element_finder, own_balls, similar_copies

BATCH = 1 << 15  # query points per RangeFinder batch (memory stays bounded)


class Compiled:
    """A CLG ready for queries: leaf tables per chunk, the auxiliary lattice, the box bound.

    ``similar`` chooses how copies are placed: None (default) similar copies exactly when U, V, W
    commute (``ple.clg.steady.similar_copies``); False the lattice's own nodes on any pattern (the
    general path, also usable on commuting patterns: tests and benchmarks compare the two)."""

    def __init__(self, clg: CLG, region=None, shell: bool = True, similar: bool | None = None):
        self.clg = clg
        self.region = region
        lat = clg.pattern
        self.lat = lat
        self.names = clg.used_chunks()
        self.chunk_id = {n: c for c, n in enumerate(self.names)}
        self.leaves = [leaves(clg.chunks[n]) for n in self.names]
        self.trees = [_index_tree(clg.chunks[n], self.leaves[c]) for c, n in enumerate(self.names)]
        self.solid = _chunk_tree(clg.solid, self.chunk_id)
        self.children = {}
        for prim, rep in clg.replacements.items():
            if rep is not None:  # a CLG is compiled; a FieldSolid answers value() itself
                self.children[prim] = (compiled(rep[0]) if isinstance(rep[0], CLG) else rep[0], rep[1])
        self.positive = [list(dict.fromkeys(positive_leaves(clg.chunks[n]))) for n in self.names]
        positive = {x.name for x in _positive_refs(clg.solid)}
        if similar and not similar_copies(lat):
            raise PleError("similar copies need commuting U, V, W (thesis §5.2)")
        self.similar = similar_copies(lat) if similar is None else bool(similar)
        if self.similar:
            self._similar_bounds(positive, shell)
        else:  # the lattice's own nodes per copy (ple.clg.steady); no spiral similarity, no conical shell
            self.finder = element_finder(lat, self.leaves, lat.region(region))
            self.aux = self.finder.aux
            ends = [(ref.n, s, ref.offset) for c, n in enumerate(self.names) if n in positive
                    for p in self.positive[c] for ref, s in ((p.a, p.sa), (p.b, p.sb)) if ref is not None]
            self.lo, self.hi = self.finder.bounds(ends)
            self.step_radius = float(np.median([x.radius for x in self.aux.nodes])) * self.aux.placement.factor
            self.shell = None
        self.scale = float(np.max(self.hi - self.lo))

    def _similar_bounds(self, positive: set, shell: bool) -> None:
        """The auxiliary lattice, box and conical shell of similar copies (module doc)."""
        lat, region = self.lat, self.region
        # bounding balls of every leaf of every chunk at group 0, in the frame G⁻¹ (see module doc)
        ginv = lat.placement.inverse()
        self.ginv = ginv.matrix
        nodes, owner = [], []
        self.balls0 = {}
        leaves = [(c, p) for c, lv in enumerate(self.leaves) for p in lv]
        for (c, p), (ca, ra, cb, rb) in zip(leaves, own_balls(lat, [p for _, p in leaves], np.zeros((1, 3), np.int64))):
            self.balls0[p] = ((ca[0], None if cb is None else cb[0]), (ra[0], None if rb is None else rb[0]))
            bc, br = (ca[0], ra[0]) if p.b is None else enclosing_ball(ca[0], ra[0], cb[0], rb[0])
            nodes.append(Node(ginv.apply_points(np.asarray(bc)[None])[0], float(br) / lat.placement.factor))
            owner.append(c)
        aux = lat.copy()
        aux.nodes, aux.beams, aux.filter = nodes, [], None
        self.aux = aux
        self.owner = np.asarray(owner, dtype=np.int64)
        keep = [m for m, c in enumerate(owner) if self.names[c] in positive]
        box = aux.copy()
        box.nodes = [nodes[m] for m in keep]
        lo, hi, exact = fast_bounds(box, region)  # end groups only, where exact (ple.model.budget)
        self.lo, self.hi = (lo, hi) if exact else box.bounds(region)
        self.step_radius = float(np.median([x.radius for x in nodes])) * lat.placement.factor
        # the conical shell (§5.5) of the positive leaves of the positive chunks, when the pattern has one
        prims = [(ca, ra, cb, rb) for c, n in enumerate(self.names) if n in positive
                 for (ca, cb), (ra, rb) in (self.balls0[p] for p in self.positive[c])]
        self.shell = conical_shell(lat, prims, region) if shell else None

    # ----- values ------------------------------------------------------------------------------------
    def value(self, points, radii=None) -> np.ndarray:
        """Clipped CSG value per point (see module doc); ``radii`` 0 (default) gives the exact sign."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        r = np.zeros(len(p)) if radii is None else np.broadcast_to(np.asarray(radii, float), (len(p),)).copy()
        out = np.empty(len(p))
        for s in range(0, len(p), BATCH):
            out[s:s + BATCH] = self._value(p[s:s + BATCH], r[s:s + BATCH])
        return out

    def combine_bool(self, unions: list) -> np.ndarray:
        """The solid from chunk-union membership arrays (one per used chunk, any equal shapes)."""
        return _eval(self.solid, [np.where(u, -1.0, 1.0) for u in unions]) <= 0

    def pmc(self, points) -> np.ndarray:
        """bool (q,): is each point in the solid (closed: on the surface counts)?"""
        return self.value(points) <= 0

    def value_event(self, points, radii, dirs, tiny: float):
        """Clipped values and, per point, the distance along ``dirs`` to the next boundary crossing
        of a primitive within the query ball (inf when none; see ``ple.clg.rays``)."""
        return self._value(np.asarray(points, float), np.asarray(radii, float), np.asarray(dirs, float), tiny)

    def _value(self, p: np.ndarray, r: np.ndarray, d=None, tiny: float = 0.0):
        far = np.where(r > 0, r, np.inf)  # what a leaf beyond the query ball is known to be
        out = far.copy()
        event = np.full(len(p), np.inf)
        idx = self.near(p, r)
        if len(idx):
            q, g, c = self.candidates(p[idx], r[idx])
            unions = np.repeat(far[idx][:, None], len(self.names), axis=1)
            ev = np.full(len(idx), np.inf)
            for ci in range(len(self.names)):
                sel = c == ci
                if not sel.any():
                    continue
                qq = q[sel]
                vals, evs = self.chunk_value(ci, p[idx][qq], g[sel], r[idx][qq],
                                             None if d is None else d[idx][qq], tiny)
                np.minimum.at(unions[:, ci], qq, vals)
                if d is not None:
                    np.minimum.at(ev, qq, evs)
            out[idx] = _combine(self.solid, unions)
            event[idx] = ev
        out = np.where(r > 0, np.clip(out, -r, r), out)
        return out if d is None else (out, event)

    def near(self, p: np.ndarray, r: np.ndarray) -> np.ndarray:
        """Indices of the query balls (p, r) that the box bound, then the conical shell, let through."""
        idx = np.nonzero(np.all((p >= self.lo - r[:, None]) & (p <= self.hi + r[:, None]), axis=1))[0]
        if self.shell is not None and len(idx):
            idx = idx[self.shell.touches(p[idx], r[idx])]
        return idx

    def candidates(self, p: np.ndarray, r: np.ndarray):
        """Unique (query, group (m, 3), chunk) triples whose primitive bounds touch ball (p, r)."""
        if not self.similar:
            return self.finder.candidates(p, r)
        if self.aux.becots is None:  # steady: the RangeFinder's flat hit rows (qid, i, j, k, n)
            rows = np.asarray(lattice_hits(self.aux, p, r)[0], dtype=np.int64).reshape(-1, 5)
            q, hits = rows[:, 0], rows[:, 1:]
        else:
            res = biq.query(self.aux, p, r)
            counts = np.fromiter((len(x.nodes) for x in res), dtype=np.int64, count=len(res))
            hits = (np.concatenate([x.nodes for x in res if len(x.nodes)]) if counts.sum()
                    else np.zeros((0, 4), np.int64))
            q = np.repeat(np.arange(len(res)), counts)
        if len(q) == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
        if self.region is not None:  # only the copies of the region's groups
            g = self.region
            keep = ((hits[:, 0] >= g.i0) & (hits[:, 0] < g.i1) & (hits[:, 1] >= g.j0) & (hits[:, 1] < g.j1)
                    & (hits[:, 2] >= g.k0) & (hits[:, 2] < g.k1))
            q, hits = q[keep], hits[keep]
        c = self.owner[hits[:, 3]]
        dims = (len(p), *self.lat.counts, len(self.names))
        key = np.unique(np.ravel_multi_index((q, hits[:, 0], hits[:, 1], hits[:, 2], c), dims))
        q, i, j, k, c = np.unravel_index(key, dims)
        return q, np.column_stack([i, j, k]), c

    def chunk_value(self, ci: int, p: np.ndarray, g: np.ndarray, r: np.ndarray, dirs=None, tiny: float = 0.0):
        """(values, next crossings or None) of chunk ``ci``'s copies at groups ``g`` (m, 3), points ``p``."""
        balls = self.prim_balls(self.leaves[ci], g)
        parts = [self.leaf_value(prim, p, b, r, dirs, tiny) for prim, b in zip(self.leaves[ci], balls)]
        vals = _eval(self.trees[ci], [x[0] for x in parts])
        return vals, (None if dirs is None else np.minimum.reduce([x[1] for x in parts]))

    def groups(self) -> np.ndarray:
        """(m, 3) indices of the groups whose chunk copies make the solid (the region's, if any)."""
        g = self.region if self.region is not None else self.lat.region(None)
        return np.stack(np.meshgrid(np.arange(g.i0, g.i1), np.arange(g.j0, g.j1), np.arange(g.k0, g.k1),
                                    indexing="ij"), -1).reshape(-1, 3)

    def copies(self, g: np.ndarray):
        """Linear parts (m, 3, 3), translations (m, 3) and factors (m,) of M_g ∘ G⁻¹ (module doc;
        similar copies only)."""
        m = self.lat.group_matrices(g[:, 0], g[:, 1], g[:, 2]) @ self.ginv
        return m[:, :3, :3], m[:, :3, 3], self.lat.group_factors(g[:, 0], g[:, 1], g[:, 2]) / self.lat.placement.factor

    def prim_balls(self, prims: list, g: np.ndarray) -> list:
        """[(ca (m, 3), ra (m,), cb (m, 3) or None, rb (m,) or None)] of each primitive's copies at
        groups ``g`` (m, 3): similar copies of the group-0 balls, or the lattice's own nodes."""
        if not self.similar:
            return own_balls(self.lat, prims, g)
        lin, move, f = self.copies(g)
        out = []
        for prim in prims:
            (ca0, cb0), (ra0, rb0) = self.balls0[prim]
            out.append((lin @ ca0 + move, f * ra0, None if cb0 is None else lin @ cb0 + move,
                        None if cb0 is None else f * rb0))
        return out

    def leaf_value(self, prim: Prim, p: np.ndarray, balls, r: np.ndarray, dirs=None, tiny: float = 0.0):
        """(signed value, next crossing along ``dirs`` or None) of a primitive's copies, given their
        ``balls`` (ca, ra, cb, rb) (``prim_balls``)."""
        ca, ra, cb, rb = balls
        d = np.linalg.norm(p - ca, axis=1) - ra if prim.b is None else beam_distance(p, ca, ra, cb, rb)
        ev = None
        if dirs is not None:
            t0, t1 = (ray_ball_interval(p, dirs, ca, ra) if prim.b is None
                      else ray_beam_interval(p, dirs, ca, ra, cb, rb))
            ev = next_crossing(t0, t1, tiny)
        child = self.children.get(prim)
        if child is None:
            return d, ev
        sub, frame = child
        need = d <= r  # elsewhere max(d, ·) is already beyond the query ball
        out = d.copy()
        if need.any():
            loc, f = to_frame(frame, p[need], ca[need], ra[need], None if cb is None else cb[need])
            dl = sub.value(loc, r[need] / f) * f
            out[need] = np.maximum(d[need], dl)
        if ev is not None:  # X entered ahead: X ∩ L is not entered before; else |value| is a safe bound
            ev = np.where(t0 > tiny, t0, np.maximum(np.abs(out), tiny))
        return out, ev


_CACHE: dict[tuple, tuple[CLG, Compiled]] = {}
CACHE_SIZE = 64


def compiled(clg: CLG, region=None) -> Compiled:
    """The Compiled form of ``clg`` (only the chunk copies of the groups of ``region``, a
    ``Region``, if given), built once per CLG object and region."""
    key = (id(clg), None if region is None else str(region))
    hit = _CACHE.get(key)
    if hit is not None and hit[0] is clg:
        return hit[1]
    comp = Compiled(clg, region)
    _CACHE[key] = (clg, comp)
    while len(_CACHE) > CACHE_SIZE:  # the add-on makes a new CLG per edit: keep the latest only
        _CACHE.pop(next(iter(_CACHE)))
    return comp


def pmc(clg: CLG, points) -> np.ndarray:
    return compiled(clg).pmc(points)


def least_rotations(e: np.ndarray) -> np.ndarray:
    """(m, 3, 3) rotations taking +x to unit rows ``e`` by the least angle; a half turn about z
    when e is −x (§10.1 beam frame)."""
    x = np.array([1.0, 0.0, 0.0])
    v = cross(np.broadcast_to(x, e.shape), e)
    c = e[:, 0]
    k = np.zeros((len(e), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    opposite = c <= -1 + 1e-12
    denom = np.where(opposite, 1.0, 1.0 + c)
    rot = np.eye(3)[None] + k + (k @ k) / denom[:, None, None]
    rot[opposite] = np.diag([-1.0, -1.0, 1.0])
    return rot


def frame_of(frame: str, ca, ra, cb):
    """(origin (m, 3), rotation (m, 3, 3), factor (m,)) of the frame that places a replacing CLG:
    the world frame, or the beam frame (origin → first centre, (1, 0, 0) → second centre); a
    ball's beam frame is its centre and radius, unrotated."""
    m = len(ca)
    if frame == "world":
        return np.zeros((m, 3)), np.broadcast_to(np.eye(3), (m, 3, 3)), np.ones(m)
    if cb is None:
        return ca, np.broadcast_to(np.eye(3), (m, 3, 3)), np.asarray(ra, float)
    ab = cb - ca
    f = np.linalg.norm(ab, axis=1)
    if np.any(f <= 0):
        raise PleError("beam frame: a beam with coincident centres has no direction")
    return ca, least_rotations(ab / f[:, None]), f


def to_frame(frame: str, p, ca, ra, cb):
    """Points ``p`` in the replacing CLG's own coordinates, and the frame factors."""
    o, rot, f = frame_of(frame, ca, ra, cb)
    return np.einsum("mji,mj->mi", rot, p - o) / f[:, None], f


# ----- expression trees as indices ------------------------------------------------------------------
def _index_tree(expr, lv: list):
    pos = iter(range(len(lv)))

    def walk(e):
        if isinstance(e, Op):
            return (e.kind, tuple(walk(a) for a in e.args))
        return next(pos)
    return walk(expr)


def _chunk_tree(expr, ids: dict):
    if isinstance(expr, ChunkRef):
        return ids[expr.name]
    return (expr.kind, tuple(_chunk_tree(a, ids) for a in expr.args))


def _eval(tree, vals: list) -> np.ndarray:
    if isinstance(tree, int):
        return vals[tree]
    kind, args = tree
    parts = [_eval(a, vals) for a in args]
    if kind == "union":
        return np.minimum.reduce(parts)
    if kind == "intersection":
        return np.maximum.reduce(parts)
    out = parts[0]
    for x in parts[1:]:
        out = np.maximum(out, -x)
    return out


def _combine(tree, unions: np.ndarray) -> np.ndarray:
    return _eval(tree, [unions[:, c] for c in range(unions.shape[1])])


def _positive_refs(expr) -> list:
    if isinstance(expr, Op):
        if expr.kind == "union":
            return [x for a in expr.args for x in _positive_refs(a)]
        return _positive_refs(expr.args[0])
    return [expr]


# ----- the reference: every primitive of every chunk copy (for benchmarks) -------------------------
def brute_force_value(clg: CLG, points, similar: bool | None = None) -> np.ndarray:
    """The naive CSG tree T of §5.5: every chunk copy at every group, O(ū v̄ w̄) per point
    (copies placed as ``Compiled(similar=...)`` places them)."""
    comp = compiled(clg) if similar is None else Compiled(clg, similar=similar)
    p = np.asarray(points, float).reshape(-1, 3)
    nu, nv, nw = clg.pattern.counts
    groups = np.stack(np.meshgrid(np.arange(nu), np.arange(nv), np.arange(nw), indexing="ij"), -1).reshape(-1, 3)
    unions = np.full((len(p), len(comp.names)), np.inf)
    step = max(1, (1 << 20) // max(1, len(groups)))
    for s in range(0, len(p), step):
        ps = p[s:s + step]
        qq = np.repeat(np.arange(len(ps)), len(groups))
        gg = np.tile(groups, (len(ps), 1))
        for ci in range(len(comp.names)):
            v = comp.chunk_value(ci, ps[qq], gg, np.zeros(len(qq)))[0]
            unions[s:s + step, ci] = v.reshape(len(ps), len(groups)).min(axis=1)
    return _combine(comp.solid, unions)
