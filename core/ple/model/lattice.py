"""Steady lattices as programs: template node-group, beam-patterns, U, V, W, placement G.

Node-group (i, j, k) is ``G ∘ W**k ∘ V**j ∘ U**i ∘ N[0,0,0]`` (thesis §6.1.2, SPEC §3); a
beam-pattern (n1, di, dj, dk, n2) joins N[i,j,k,n1] to N[i+di,j+dj,k+dk,n2] wherever both
exist (§2.1.2). Nothing is evaluated until asked: every evaluation takes index arrays or a
region and costs memory proportional to what it returns.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from ..algebra.series import geometric_sum
from ..algebra.similarity import Similarity
from ..algebra.vectors import Pt
from ..errors import PleError, echo
from .becots import BeCOTS, BeCOTSField, Stack, becots_counts
from .grading import RadiusField
from .groupmap import GroupMap

MAX_COUNT = 10**7  # per direction; beyond this a count is certainly a typo
MAX_GROUPS = 10**13
MAX_EXPLICIT_NODES = 200_000  # Lattice.explicit: one template node per node, per-hub work


@dataclass
class Node:
    """A template ball: ``center`` (3,), ``radius`` > 0, optional ``name``."""

    center: np.ndarray
    radius: float
    name: str | None = None


@dataclass(frozen=True)
class BeamPattern:
    """Joins node ``n1`` of group (i, j, k) to node ``n2`` of group (i+di, j+dj, k+dk)."""

    n1: int
    n2: int
    di: int
    dj: int
    dk: int

    @property
    def offset(self) -> tuple[int, int, int]:
        return (self.di, self.dj, self.dk)


@dataclass(frozen=True)
class Direction:
    """A repetition count and its similarity, given incrementally or cumulatively (§2.6.2)."""

    count: int = 1
    similarity: Similarity = field(default_factory=Similarity)
    cumulative: bool = False

    @property
    def incremental(self) -> Similarity:
        """The per-step similarity; a cumulative S spans groups 0 .. count-1: S**(1/(count-1))."""
        if not self.cumulative:
            return self.similarity
        if self.count <= 1:
            return Similarity()
        return self.similarity ** (1.0 / (self.count - 1))


@dataclass(frozen=True)
class Region:
    """Half-open index box ``[i0, i1) × [j0, j1) × [k0, k1)``."""

    i0: int
    i1: int
    j0: int
    j1: int
    k0: int
    k1: int

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.i1 - self.i0, self.j1 - self.j0, self.k1 - self.k0)

    @property
    def groups(self) -> int:
        a, b, c = self.shape
        return a * b * c

    def __str__(self) -> str:
        return f"{self.i0}:{self.i1},{self.j0}:{self.j1},{self.k0}:{self.k1}"

    def node_index(self, nn: int) -> np.ndarray:
        """(i, j, k, n) of every node of the box for ``nn`` template nodes: (N, 4) int64 in
        (i, j, k, n) order — the row order of every region evaluation."""
        ni, nj, nk = self.shape
        out = np.empty((ni, nj, nk, nn, 4), dtype=np.int64)
        out[..., 0] = np.arange(self.i0, self.i1)[:, None, None, None]
        out[..., 1] = np.arange(self.j0, self.j1)[None, :, None, None]
        out[..., 2] = np.arange(self.k0, self.k1)[None, None, :, None]
        out[..., 3] = np.arange(nn)
        return out.reshape(-1, 4)

    @staticmethod
    def parse(text: str) -> Region:
        """Parse ``I0:I1,J0:J1,K0:K1`` (half-open; an empty bound means the lattice's)."""
        parts = text.split(",")
        if len(parts) != 3:
            raise PleError(f"region {echo(text)}: expected I0:I1,J0:J1,K0:K1")
        vals: list[int | None] = []
        for part in parts:
            ab = part.split(":")
            if len(ab) != 2:
                raise PleError(f"region {echo(text)}: each axis must read A:B, got {echo(part)}")
            for x in ab:
                try:
                    vals.append(int(x) if x.strip() else None)
                except ValueError:
                    raise PleError(f"region {echo(text)}: {echo(x)} is not an integer") from None
        return _OpenRegion(*vals)  # resolved against the lattice by Lattice.region()


@dataclass(frozen=True)
class _OpenRegion:
    i0: int | None
    i1: int | None
    j0: int | None
    j1: int | None
    k0: int | None
    k1: int | None


@dataclass
class Evaluation:
    """Evaluated nodes and beams of a region (the arrays of ``ple eval``).

    node_index (N, 4) int64: i, j, k, n; center (N, 3); radius (N,);
    beam_index (M, 4) int64: i, j, k, pattern of the beam's *from* group;
    beam_nodes (M, 2) int64: rows of the node arrays.
    """

    node_index: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    beam_index: np.ndarray
    beam_nodes: np.ndarray

    def arrays(self) -> dict[str, np.ndarray]:
        return {"node_index": self.node_index, "center": self.center, "radius": self.radius,
                "beam_index": self.beam_index, "beam_nodes": self.beam_nodes}

    def select(self, keep: np.ndarray) -> Evaluation:
        """Keep the nodes flagged in ``keep`` (N,) and the beams whose two nodes are both kept;
        beam_nodes are renumbered to rows of the kept nodes."""
        keep = np.asarray(keep, dtype=bool)
        new_row = np.cumsum(keep) - 1
        beam_alive = keep[self.beam_nodes[:, 0]] & keep[self.beam_nodes[:, 1]] if len(self.beam_nodes) else \
            np.zeros(0, dtype=bool)
        return Evaluation(self.node_index[keep], self.center[keep], self.radius[keep], self.beam_index[beam_alive],
                          new_row[self.beam_nodes[beam_alive]].reshape(-1, 2).astype(np.int64))


class Lattice:
    """A steady lattice program (SPEC §4). Build with add_node/add_beam/set_u/set_v/set_w."""

    def __init__(self) -> None:
        self.nodes: list[Node] = []
        self.beams: list[BeamPattern] = []
        self.u = Direction()
        self.v = Direction()
        self.w = Direction()
        self.placement = Similarity()
        self.becots = None  # a BeCOTS description for corner-operated slabs (set_becots, set_field)
        self.filter = None  # an optional ple.filters.Filter deciding which nodes survive (thesis §9)
        self.group_map = None  # a GroupMap placing the groups instead of U, V, W, G (Möbius, warps)
        self.radius_field = None  # an optional grading.RadiusField multiplying node radii
        self.meta: dict = {}

    # ----- building -----------------------------------------------------------------------
    def add_node(self, center, radius: float, name: str | None = None) -> int:
        """Add a template ball; returns its node id (its position in ``nodes``)."""
        c = Pt(center)
        r = float(radius)
        if not math.isfinite(r) or r <= 0:
            raise PleError(f"node radius must be a positive number, got {echo(radius)}")
        names = self._names()
        if name is not None and name in names and any(n.name == name for n in self.nodes):
            raise PleError(f"node id {echo(name)} is used twice")
        self.nodes.append(Node(c, r, name))
        if name is not None:
            names[name] = len(self.nodes) - 1
        self._names_key = (id(self.nodes), len(self.nodes))
        return len(self.nodes) - 1

    def _names(self) -> dict:
        """Node name -> position (the first node of that name), rebuilt when ``nodes`` is another
        list or has another length: thousands of named nodes are added and resolved in linear time."""
        key = (id(self.nodes), len(self.nodes))
        if getattr(self, "_names_key", None) != key:
            names: dict = {}
            for idx, node in enumerate(self.nodes):
                if node.name is not None:
                    names.setdefault(node.name, idx)
            self._name_ids, self._names_key = names, key
        return self._name_ids

    def node_id(self, ref) -> int:
        """Resolve a node reference (int position or string name) to its position."""
        if isinstance(ref, (bool, np.bool_)):
            raise PleError(f"unknown node id {echo(ref)}")
        if isinstance(ref, (int, np.integer)):
            if 0 <= int(ref) < len(self.nodes):
                return int(ref)
            raise PleError(f"unknown node id {echo(ref)} (the template has {len(self.nodes)} nodes)")
        idx = self._names().get(ref)
        if idx is not None and self.nodes[idx].name == ref:
            return idx
        for idx, node in enumerate(self.nodes):  # a node renamed in place since the names were listed
            if node.name == ref:
                return idx
        raise PleError(f"unknown node id {echo(ref)}")

    def add_beam(self, n1, n2, di: int = 0, dj: int = 0, dk: int = 0) -> int:
        """Add beam-pattern (n1, di, dj, dk, n2); returns its index."""
        a, b = self.node_id(n1), self.node_id(n2)
        offs = []
        for name, d in (("di", di), ("dj", dj), ("dk", dk)):
            if int(d) != d:
                raise PleError(f"beam offset {name} must be an integer, got {echo(d)}")
            offs.append(int(d))
        if a == b and offs == [0, 0, 0]:
            raise PleError(f"beam from node {echo(n1)} to itself with offset 0,0,0 has no length")
        self.beams.append(BeamPattern(a, b, *offs))
        return len(self.beams) - 1

    def remove_beam(self, index: int) -> None:
        if not 0 <= index < len(self.beams):
            raise PleError(f"unknown beam-pattern {index}")
        del self.beams[index]

    def remove_node(self, ref) -> None:
        """Remove a template node and every beam-pattern that uses it."""
        n = self.node_id(ref)
        del self.nodes[n]
        shift = lambda m: m - 1 if m > n else m  # noqa: E731
        self.beams = [BeamPattern(shift(b.n1), shift(b.n2), b.di, b.dj, b.dk)
                      for b in self.beams if n not in (b.n1, b.n2)]

    def _direction(self, name: str, count, similarity: Similarity, cumulative: bool) -> Direction:
        if isinstance(count, bool) or int(count) != count:
            raise PleError(f"{name} count must be an integer, got {echo(count)}")
        count = int(count)
        if count < 1:
            raise PleError(f"{name} count must be at least 1, got {count}")
        if count > MAX_COUNT:
            raise PleError(f"{name} count {count} is absurdly large (limit {MAX_COUNT})")
        if not isinstance(similarity, Similarity):
            raise PleError(f"{name} similarity must be a Similarity, got {type(similarity).__name__}")
        return Direction(count, similarity, bool(cumulative))

    def set_u(self, count: int, similarity: Similarity, cumulative: bool = False) -> None:
        self.u = self._direction("U", count, similarity, cumulative)
        self._check_size()

    def set_v(self, count: int, similarity: Similarity, cumulative: bool = False) -> None:
        self.v = self._direction("V", count, similarity, cumulative)
        self._check_size()

    def set_w(self, count: int, similarity: Similarity, cumulative: bool = False) -> None:
        self.w = self._direction("W", count, similarity, cumulative)
        self._check_size()

    def set_placement(self, similarity: Similarity) -> None:
        if not isinstance(similarity, Similarity):
            raise PleError("placement must be a Similarity")
        self.placement = similarity

    def set_becots(self, a, b, c, d, counts=(1, 1), branch=(0, 0), closed: bool = False) -> None:
        """A BeCOTS slab from four corners (M(0,0)=A, M(0,1)=B, M(1,1)=C, M(1,0)=D, thesis
        §4.2): sets U and V from the corner-operated field (see ``ple.model.becots``)."""
        self.set_field(BeCOTSField.from_corners(a, b, c, d, branch), counts, closed)

    def set_field(self, fld: BeCOTSField, counts=(1, 1), closed: bool = False, stack: Stack | None = None) -> None:
        """Make this lattice a BeCOTS slab of field ``fld``: node-group (i, j) = S(i/nu, j/nv) ∘ template."""
        nu, nv = becots_counts(counts)
        info = BeCOTS(fld, (nu, nv), bool(closed), stack)
        gu, gv = info.group_counts
        self.set_u(gu, info.U)
        self.set_v(gv, info.V)
        self.becots = info

    def set_group_map(self, gmap: GroupMap, counts=(1, 1, 1)) -> None:
        """Place node-group (i, j, k) by ``gmap`` (a GroupMap: Möbius patterns, rectified warps)
        instead of similarities; ``counts`` = (nu, nv[, nw]) groups. U, V, W become identities."""
        if not isinstance(gmap, GroupMap):
            raise PleError(f"group map must be a GroupMap, got {type(gmap).__name__}")
        counts = tuple(counts)
        if not 1 <= len(counts) <= 3:
            raise PleError(f"group map counts {echo(counts)}: expected (nu, nv[, nw])")
        nu, nv, nw = counts + (1,) * (3 - len(counts))
        self.u, self.v, self.w = (self._direction(name, c, Similarity(), False)
                                  for name, c in (("U", nu), ("V", nv), ("W", nw)))
        self.placement, self.becots = Similarity(), None
        self._check_size()
        self.group_map = gmap

    def set_filter(self, node_filter) -> None:
        """Keep only the nodes a filter accepts (stencil, LiL, implicit field, … ; thesis §9);
        beams survive where both nodes do. The filter is part of the lattice: every evaluation,
        query, measure and mesh of it sees only what the filter keeps."""
        if node_filter is not None and not callable(getattr(node_filter, "node_mask", None)):
            raise PleError(f"filter must be a ple filter (Stencil, LiL, ImplicitFilter, …), "
                           f"got {type(node_filter).__name__}")
        self.filter = node_filter

    def set_radius_field(self, field) -> None:
        """Grade the thickness: node radii are multiplied by ``field`` at their centres
        (``ple.model.grading``); None makes the radii steady again."""
        if field is not None and not isinstance(field, RadiusField):
            raise PleError(f"radius field must be a RadiusField (LinearGradient, GridField, FunctionField, …), "
                           f"got {type(field).__name__}")
        self.radius_field = field

    def bounding_lattice(self) -> Lattice:
        """The steady lattice whose balls contain this one's graded balls (radii × the field's
        bound, no field): candidate searches use it, exact tests the true radii."""
        other = self.copy()
        if self.radius_field is not None:
            for node in other.nodes:
                node.radius *= self.radius_field.bound
            other.radius_field = None
        return other

    def with_filter(self, node_filter) -> Lattice:
        """A copy whose filter keeps what this lattice's filter and ``node_filter`` both keep
        (this one's first: a program's own filter, then a command's or a panel's)."""
        other = self.copy()
        if node_filter is not None:
            other.set_filter(node_filter if self.filter is None else self.filter & node_filter)
        return other

    def unfiltered(self) -> Lattice:
        """The same program without its filter (every node of every group)."""
        other = self.copy()
        other.filter = None
        return other

    def _check_size(self) -> None:
        if self.groups > MAX_GROUPS:
            raise PleError(f"{self.groups:.3g} node-groups is absurdly large (limit {MAX_GROUPS:.0e})")

    def copy(self) -> Lattice:
        other = Lattice()
        other.nodes = [Node(n.center.copy(), n.radius, n.name) for n in self.nodes]
        other.beams = list(self.beams)
        other.u, other.v, other.w, other.placement = self.u, self.v, self.w, self.placement
        other.becots, other.filter, other.meta = self.becots, self.filter, dict(self.meta)
        other.group_map = self.group_map
        other.radius_field = self.radius_field
        return other

    # ----- shape ----------------------------------------------------------------------------
    @property
    def counts(self) -> tuple[int, int, int]:
        return (self.u.count, self.v.count, self.w.count)

    @property
    def groups(self) -> int:
        a, b, c = self.counts
        return a * b * c

    @property
    def U(self) -> Similarity:  # noqa: N802 - thesis names
        return self.u.incremental

    @property
    def V(self) -> Similarity:  # noqa: N802
        return self.v.incremental

    @property
    def W(self) -> Similarity:  # noqa: N802
        return self.w.incremental

    @property
    def template_centers(self) -> np.ndarray:
        return np.array([n.center for n in self.nodes], dtype=float).reshape(-1, 3)

    @property
    def template_radii(self) -> np.ndarray:
        return np.array([n.radius for n in self.nodes], dtype=float)

    def validate(self) -> None:
        """Raise PleError if the lattice cannot be evaluated (no nodes)."""
        if not self.nodes:
            raise PleError("the lattice has no nodes")

    def node_count(self, region=None) -> int:
        """Nodes of the program in a region (default: all), before any filter."""
        return self.region(region).groups * len(self.nodes)

    def beam_count(self, region=None) -> int:
        """Beams of the program with both ends in a region (default: all), before any filter:
        per pattern, the groups of the region whose offset partner is in it too."""
        r = self.region(region)
        total = 0
        for b in self.beams:
            total += math.prod(max(0, c - abs(d)) for c, d in zip(r.shape, b.offset))
        return total

    def region(self, region=None) -> Region:
        """The full index box, or ``region`` (Region, open region or text) clamped-checked."""
        nu, nv, nw = self.counts
        if region is None:
            return Region(0, nu, 0, nv, 0, nw)
        if isinstance(region, str):
            region = Region.parse(region)
        vals = [region.i0, region.i1, region.j0, region.j1, region.k0, region.k1]
        lims = [nu, nu, nv, nv, nw, nw]
        out = []
        for pos, (x, lim) in enumerate(zip(vals, lims)):
            if x is None:
                x = 0 if pos % 2 == 0 else lim
            if x < 0:
                x += lim
            out.append(int(x))
        r = Region(*out)
        for axis, (a, b, lim) in enumerate(zip(out[::2], out[1::2], (nu, nv, nw))):
            if not 0 <= a < b <= lim:
                raise PleError(f"region {r}: axis {'ijk'[axis]} range {a}:{b} is empty or outside 0:{lim}")
        return r

    # ----- evaluation -------------------------------------------------------------------------
    def _similarity_groups(self, what: str) -> None:
        if self.group_map is not None:
            raise PleError(f"{what}: this lattice's groups are placed by a {self.group_map.kind} map, "
                           "not by similarities (use Lattice.explicit for per-hub work)")

    def group_matrices(self, i, j, k) -> np.ndarray:
        """Matrices of ``G ∘ W**k ∘ V**j ∘ U**i`` for index arrays, shape (N, 4, 4)."""
        self._similarity_groups("group matrices")
        mu, mv, mw = (_power_table(s, np.asarray(x).reshape(-1))
                      for s, x in ((self.U, i), (self.V, j), (self.W, k)))
        return self.placement.matrix[None] @ (mw @ (mv @ mu))

    def group_factors(self, i, j, k) -> np.ndarray:
        """Dilation factor of group (i, j, k): s_G s_W**k s_V**j s_U**i, shape (N,)."""
        self._similarity_groups("group factors")
        i, j, k = (np.asarray(x, dtype=float).reshape(-1) for x in (i, j, k))
        return (self.placement.factor * self.W.factor ** k * self.V.factor ** j * self.U.factor ** i)

    def node_balls(self, index) -> tuple[np.ndarray, np.ndarray]:
        """Centres (N, 3) and radii (N,) of nodes given as an (N, 4) array of (i, j, k, n)."""
        self.validate()
        idx = np.asarray(index, dtype=np.int64).reshape(-1, 4)
        if self.group_map is not None:
            return self.group_map.map_balls(idx[:, 0], idx[:, 1], idx[:, 2], self.template_centers[idx[:, 3]],
                                            self.template_radii[idx[:, 3]])
        m = self.group_matrices(idx[:, 0], idx[:, 1], idx[:, 2])
        c = self.template_centers[idx[:, 3]]
        centers = np.einsum("nab,nb->na", m[:, :3, :3], c) + m[:, :3, 3]
        radii = self.template_radii[idx[:, 3]] * self.group_factors(idx[:, 0], idx[:, 1], idx[:, 2])
        if self.radius_field is not None:
            radii = radii * self.radius_field.factors(centers)
        return centers, radii

    def region_balls(self, region=None) -> tuple[np.ndarray, np.ndarray]:
        """Centres (ni, nj, nk, nn, 3) and radii (ni, nj, nk, nn) of a region, vectorized."""
        self.validate()
        r = self.region(region)
        if self.group_map is not None:
            c, rad = self.node_balls(r.node_index(len(self.nodes)))
            return c.reshape(*r.shape, len(self.nodes), 3), rad.reshape(*r.shape, len(self.nodes))
        ii, jj, kk = np.arange(r.i0, r.i1), np.arange(r.j0, r.j1), np.arange(r.k0, r.k1)
        mu = self.U.power_matrices(ii)
        # G ∘ W^k ∘ V^j for all (j, k): small (nj * nk matrices)
        mw, mv = self.W.power_matrices(kk), self.V.power_matrices(jj)
        mvw = self.placement.matrix[None, None] @ mw[None, :] @ mv[:, None]
        c = self.template_centers
        a = np.einsum("iab,nb->ina", mu[:, :3, :3], c) + mu[:, None, :3, 3]  # (ni, nn, 3)
        ni, nn = a.shape[:2]
        lin = mvw[..., :3, :3].reshape(-1, 3, 3)  # (nj*nk, 3, 3)
        pts = lin @ a.reshape(-1, 3).T + mvw[..., :3, 3].reshape(-1, 3, 1)  # (nj*nk, 3, ni*nn)
        centers = pts.reshape(len(jj), len(kk), 3, ni, nn).transpose(3, 0, 1, 4, 2)
        f = (self.placement.factor * self.U.factor ** ii[:, None, None] * self.V.factor ** jj[None, :, None]
             * self.W.factor ** kk[None, None, :])
        radii = f[..., None] * self.template_radii
        if self.radius_field is not None:
            radii = radii * self.radius_field.factors(centers.reshape(-1, 3)).reshape(radii.shape)
        return np.ascontiguousarray(centers), radii

    def region_beams(self, region=None) -> tuple[np.ndarray, np.ndarray]:
        """Beams with both ends in the region: beam_index (M, 4) and beam_nodes (M, 2) rows
        of the region's flattened node arrays (order i, j, k, n), sorted by (i, j, k, pattern)."""
        r = self.region(region)
        flat, ends = self._beam_rows(r, np.int64)
        idx = np.empty((len(flat), 4), np.int64)
        group, idx[:, 3] = np.divmod(flat, max(len(self.beams), 1))
        rest, idx[:, 2] = np.divmod(group, r.shape[2])
        idx[:, 0], idx[:, 1] = np.divmod(rest, r.shape[1])
        idx[:, :3] += (r.i0, r.j0, r.k0)
        return idx, ends

    def region_beam_nodes(self, region=None, dtype=np.int64) -> np.ndarray:
        """The beam_nodes of ``region_beams`` alone, as ``dtype`` (int32: a drawing's edge
        vertices, half the memory): a drawing needs no beam_index."""
        r = self.region(region)
        if np.dtype(dtype).itemsize < 8 and r.groups * len(self.nodes) > np.iinfo(dtype).max:
            raise PleError(f"region {r}: {r.groups * len(self.nodes)} nodes do not fit {np.dtype(dtype).name} rows")
        return self._beam_rows(r, dtype)[1]

    def _beam_rows(self, r: Region, dtype) -> tuple[np.ndarray, np.ndarray]:
        """(flat (group, pattern) numbers, beam_nodes as ``dtype``) of the beams with both ends in ``r``."""
        ni, nj, nk = r.shape
        nn, npat = len(self.nodes), len(self.beams)
        if not self.beams or not r.groups:
            return np.zeros(0, np.int64), np.zeros((0, 2), dtype)
        off = np.array([b.offset for b in self.beams], np.int64)
        # which (group, pattern) pairs have both ends in the region: nonzero lists them in (i, j, k, p) order
        valid = np.ones((ni, nj, nk, npat), bool)
        for d, size in enumerate((ni, nj, nk)):
            x = np.arange(size)[:, None] + off[:, d][None]
            shape = [1, 1, 1, npat]
            shape[d] = size
            valid &= ((x >= 0) & (x < size)).reshape(shape)
        n1 = np.array([b.n1 for b in self.beams], np.int64)
        n2 = np.array([b.n2 for b in self.beams], np.int64)
        step = ((off[:, 0] * nj + off[:, 1]) * nk + off[:, 2]) * nn + n2  # row offset of each pattern's far end
        flat = np.flatnonzero(valid)
        group, pattern = np.divmod(flat, npat)
        group *= nn  # the row of the group's first node
        ends = np.empty((len(flat), 2), dtype)  # written in place: no stacked copies
        np.add(group, n1[pattern], out=ends[:, 0], casting="unsafe")
        np.add(group, step[pattern], out=ends[:, 1], casting="unsafe")
        return flat, ends

    def evaluate(self, region=None) -> Evaluation:
        """The nodes and beams of a region (default: the whole lattice) that the lattice's filter
        keeps (all of them without a filter): the one evaluation every door uses."""
        r = self.region(region)
        if self.filter is None:
            return self.evaluate_unfiltered(r)
        ev, rows = self.region_rows(r)
        ev.beam_index, ev.beam_nodes = beams_between(self, r, rows, r, rows)
        return ev

    def evaluate_steps(self, region=None, max_groups: int = 1 << 14) -> Iterator[float]:
        """``evaluate(region)`` with the filter asked box by box (``iter_slabs``): a generator
        yielding the fraction of node-groups done after each box and returning the Evaluation
        (the same arrays), so that a caller can show progress and stop between boxes."""
        r = self.region(region)
        if self.filter is None:
            return self.evaluate_unfiltered(r)
        centers, radii = self.region_balls(r)
        nn = len(self.nodes)
        keep = np.zeros(radii.shape, dtype=bool)
        done = 0
        for box in self.iter_slabs(max_groups, r):
            sel = (slice(box.i0 - r.i0, box.i1 - r.i0), slice(box.j0 - r.j0, box.j1 - r.j0),
                   slice(box.k0 - r.k0, box.k1 - r.k0))
            keep[sel] = self.keeps(box.node_index(nn), centers[sel].reshape(-1, 3),
                                   radii[sel].reshape(-1)).reshape(keep[sel].shape)
            done += box.groups
            yield done / r.groups
        ev, rows = self.region_rows(r, keep.reshape(-1), (centers, radii))
        ev.beam_index, ev.beam_nodes = beams_between(self, r, rows, r, rows)
        return ev

    def first_kept_group(self, max_groups: int = 1 << 12) -> tuple[int, int, int] | None:
        """(i, j, k) of the first node-group, in ``iter_slabs`` order, of which the filter keeps a
        node: (0, 0, 0) without a filter, None when it keeps nothing. The filter is asked box by
        box and the search stops at the first box that keeps a node (where a drawing of a
        filtered lattice starts, when its first corner keeps nothing)."""
        if self.filter is None:
            return (0, 0, 0)
        nn = len(self.nodes)
        for box in self.iter_slabs(max_groups, self.region()):
            centers, radii = self.region_balls(box)
            idx = box.node_index(nn)
            keep = np.asarray(self.keeps(idx, centers.reshape(-1, 3), radii.reshape(-1)), bool)
            if keep.any():
                return tuple(int(x) for x in idx[np.flatnonzero(keep)[0], :3])
        return None

    def evaluate_unfiltered(self, region=None) -> Evaluation:
        """Every node and beam of a region, ignoring the filter (the steady program itself)."""
        r = self.region(region)
        centers, radii = self.region_balls(r)
        beam_index, beam_nodes = self.region_beams(r)
        return Evaluation(r.node_index(len(self.nodes)), centers.reshape(-1, 3), radii.reshape(-1), beam_index,
                          beam_nodes)

    def iter_evaluation(self, region=None, max_groups: int = 1 << 18) -> Iterator[tuple[Region, Evaluation]]:
        """The evaluation of a region streamed slab by slab (``iter_slabs``), memory bounded by one
        slab plus the few i-layers a beam offset reaches: per slab, its kept nodes and the beams
        completed in it (those whose later end lies in it); ``beam_nodes`` are global rows into
        the concatenation of all slabs' nodes. Concatenated, the slabs are ``evaluate(region)``."""
        r = self.region(region)
        reach_i = max((abs(b.di) for b in self.beams), default=0)
        retained: list[tuple] = []  # (slab, global row map) of earlier slabs a beam may still reach
        offset = 0
        for slab in self.iter_slabs(max_groups, r):
            nodes, rows = self.region_rows(slab)
            rows = np.where(rows >= 0, rows + offset, -1)
            retained = [(s, m) for s, m in retained if s.i1 - 1 + reach_i >= slab.i0]
            parts = [beams_between(self, slab, rows, slab, rows)]
            for s, m in retained:
                parts.append(beams_between(self, s, m, slab, rows))
                parts.append(beams_between(self, slab, rows, s, m))
            idx = np.concatenate([p[0] for p in parts])
            ends = np.concatenate([p[1] for p in parts])
            order = np.lexsort((idx[:, 3], idx[:, 2], idx[:, 1], idx[:, 0]))
            nodes.beam_index, nodes.beam_nodes = idx[order], ends[order]
            yield slab, nodes
            offset += len(nodes.node_index)
            retained.append((slab, rows))

    def keeps(self, index, centers=None, radii=None) -> np.ndarray:
        """bool (N,): which nodes (N, 4) of (i, j, k, n) the filter keeps (all without one); their
        balls are computed unless given. Indices outside the counts are never kept."""
        idx = np.asarray(index, dtype=np.int64).reshape(-1, 4)
        inside = np.all((idx[:, :3] >= 0) & (idx[:, :3] < np.array(self.counts)), axis=1)
        if self.filter is None or not inside.any():
            return inside
        if centers is None:
            centers, radii = self.node_balls(idx)
        keep = np.zeros(len(idx), dtype=bool)
        rows = np.flatnonzero(inside)
        keep[rows] = self.filter.node_mask(self, idx[rows], np.asarray(centers)[rows], np.asarray(radii)[rows])
        return keep

    def region_rows(self, region=None, keep=None, balls=None) -> tuple[Evaluation, np.ndarray]:
        """Kept nodes of a region (an Evaluation without beams) and the region's row map: int64
        (ni, nj, nk, nn), each kept node's row or -1 for a removed node (for streaming).
        ``keep`` (N,) and ``balls`` (``region_balls``) when already computed."""
        r = self.region(region)
        centers, radii = self.region_balls(r) if balls is None else balls
        index = r.node_index(len(self.nodes))
        if keep is None:
            keep = self.keeps(index, centers.reshape(-1, 3), radii.reshape(-1))
        rows = np.where(keep, np.cumsum(keep) - 1, -1).reshape(radii.shape)
        nodes = Evaluation(index[keep], centers.reshape(-1, 3)[keep], radii.reshape(-1)[keep],
                           np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64))
        return nodes, rows

    def beams_of_pattern(self, pattern: int, i, j, k):
        """For from-groups given as index arrays: (valid (N,) bool, from-ball, to-ball).

        A beam exists where both its groups are inside the lattice; balls are returned as
        (centres (N, 3), radii (N,)) for every input, valid or not."""
        b = self.beams[pattern]
        i, j, k = (np.asarray(x, dtype=np.int64).reshape(-1) for x in (i, j, k))
        nu, nv, nw = self.counts
        ti, tj, tk = i + b.di, j + b.dj, k + b.dk
        valid = ((i >= 0) & (i < nu) & (j >= 0) & (j < nv) & (k >= 0) & (k < nw)
                 & (ti >= 0) & (ti < nu) & (tj >= 0) & (tj < nv) & (tk >= 0) & (tk < nw))
        start = self.node_balls(np.stack([i, j, k, np.full_like(i, b.n1)], axis=1))
        end = self.node_balls(np.stack([ti, tj, tk, np.full_like(i, b.n2)], axis=1))
        return valid, start, end

    def row_w(self, i: int, j: int, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The steady row of node n along W at (i, j): centres (nw, 3) and radii (nw,)."""
        nw = self.w.count
        idx = np.stack([np.full(nw, i), np.full(nw, j), np.arange(nw), np.full(nw, n)], axis=1)
        return self.node_balls(idx)

    def iter_slabs(self, max_groups: int = 1 << 18, region=None) -> Iterator[Region]:
        """Split a region into boxes of at most ``max_groups`` groups (whole k-rows, then
        j-slabs), in (i, j, k) order, for streaming over lattices larger than memory."""
        r = self.region(region)
        ni, nj, nk = r.shape
        if nk > max_groups:
            for i in range(r.i0, r.i1):
                for j in range(r.j0, r.j1):
                    for k in range(r.k0, r.k1, max_groups):
                        yield Region(i, i + 1, j, j + 1, k, min(k + max_groups, r.k1))
            return
        rows = max(1, max_groups // nk)
        if rows < nj:
            for i in range(r.i0, r.i1):
                for j in range(r.j0, r.j1, rows):
                    yield Region(i, i + 1, j, min(j + rows, r.j1), r.k0, r.k1)
            return
        slabs = max(1, max_groups // (nj * nk))
        for i in range(r.i0, r.i1, slabs):
            yield Region(i, min(i + slabs, r.i1), r.j0, r.j1, r.k0, r.k1)

    def bounds(self, region=None) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds (min (3,), max (3,)) of all balls, streamed over slabs."""
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for part in self.iter_slabs(region=region):
            c, rad = self.region_balls(part)
            c, rad = c.reshape(-1, 3), rad.reshape(-1, 1)
            lo = np.minimum(lo, (c - rad).min(axis=0))
            hi = np.maximum(hi, (c + rad).max(axis=0))
        return lo, hi

    def mean_radius(self) -> float:
        """Mean ball radius over the whole lattice, in closed form (geometric series); with a
        group map or a radius field, streamed over slabs."""
        if self.group_map is not None or self.radius_field is not None:
            total = sum(float(self.region_balls(part)[1].sum()) for part in self.iter_slabs())
            return total / self.node_count()
        f = 1.0
        for s, n in ((self.U, self.u.count), (self.V, self.v.count), (self.W, self.w.count)):
            f *= geometric_sum(s.factor, n) / n
        return float(self.placement.factor * f * self.template_radii.mean())

    def explicit(self, region=None) -> Lattice:
        """The region as a one-group lattice whose template holds every (filter-kept) node and
        whose beam-patterns (offset 0) are the region's beams: the general per-hub form for
        lattices whose groups are not similar (group maps). Bounded by MAX_EXPLICIT_NODES."""
        r = self.region(region)
        nn = len(self.nodes)
        if r.groups * nn > MAX_EXPLICIT_NODES:
            raise PleError(f"region {r} has {r.groups * nn:,} nodes; the per-hub path handles at most "
                           f"{MAX_EXPLICIT_NODES:,}: choose a smaller region")
        idx = r.node_index(nn)
        c, rad = self.node_balls(idx)
        keep = np.ones(len(idx), bool)
        if self.filter is not None:
            keep = np.asarray(self.filter.node_mask(self, idx, c, rad), dtype=bool)
        row = np.cumsum(keep) - 1
        out = Lattice()
        out.nodes = [Node(c[q].copy(), float(rad[q])) for q in np.flatnonzero(keep)]
        _, bn = self.region_beams(r)
        bn = bn[keep[bn[:, 0]] & keep[bn[:, 1]]]
        out.beams = [BeamPattern(int(row[a]), int(row[b]), 0, 0, 0) for a, b in bn]
        out.meta = dict(self.meta, explicit_of=str(r))
        return out

    def per_hub(self, region=None) -> tuple[Lattice, Region]:
        """This lattice and its region as per-hub work sees them: unchanged when similarities place
        the groups; for a group map (Möbius, TMI), whose hubs are exact images but not similar
        copies, ``explicit`` (every hub its own template node) and its one-group region."""
        r = self.region(region)
        if self.group_map is None:
            return self, r
        out = self.explicit(r)
        return out, out.region()

    def with_counts(self, nu: int, nv: int, nw: int) -> Lattice:
        """A copy with other repetition counts and the same incremental similarities."""
        other = self.copy()
        other.u = replace(self.u, count=nu, similarity=self.U, cumulative=False)
        other.v = replace(self.v, count=nv, similarity=self.V, cumulative=False)
        other.w = replace(self.w, count=nw, similarity=self.W, cumulative=False)
        return other


def beams_between(lat: Lattice, a: Region, rows_a: np.ndarray, b: Region, rows_b: np.ndarray):
    """Beams whose from-group lies in box ``a`` and to-group in box ``b``, both nodes alive.

    ``rows_a``/``rows_b`` (ni, nj, nk, nn) give each node's output row, -1 where removed.
    Returns beam_index (M, 4) and beam_nodes (M, 2), sorted by (i, j, k, pattern)."""
    lo_all, hi_all, boxes = np.full(3, np.iinfo(np.int64).max), np.full(3, np.iinfo(np.int64).min), []
    for p, bp in enumerate(lat.beams):
        lo = np.maximum((a.i0, a.j0, a.k0), np.subtract((b.i0, b.j0, b.k0), bp.offset))
        hi = np.minimum((a.i1, a.j1, a.k1), np.subtract((b.i1, b.j1, b.k1), bp.offset))
        if np.all(hi > lo):
            boxes.append((p, bp, lo, hi))
            lo_all, hi_all = np.minimum(lo_all, lo), np.maximum(hi_all, hi)
    if not boxes:
        return np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64)
    # one Boolean array over (i, j, k, pattern): np.nonzero then lists beams already sorted
    alive = np.zeros((*(hi_all - lo_all), len(lat.beams)), dtype=bool)
    a0, b0 = np.array((a.i0, a.j0, a.k0)), np.array((b.i0, b.j0, b.k0))
    keep_a = rows_a >= 0
    keep_b = keep_a if rows_b is rows_a else rows_b >= 0
    for p, bp, lo, hi in boxes:
        fa = keep_a[tuple(slice(x, y) for x, y in zip(lo - a0, hi - a0)) + (bp.n1,)]
        tb = keep_b[tuple(slice(x, y) for x, y in zip(lo + bp.offset - b0, hi + bp.offset - b0)) + (bp.n2,)]
        np.logical_and(fa, tb, out=alive[tuple(slice(x, y) for x, y in zip(lo - lo_all, hi - lo_all)) + (p,)])
    flat = np.flatnonzero(alive)  # linear (i, j, k, pattern) positions, in sorted order
    nb = len(lat.beams)
    ext = hi_all - lo_all
    pp = flat % nb
    g = flat // nb
    kk = g % ext[2] + lo_all[2]
    g //= ext[2]
    jj = g % ext[1] + lo_all[1]
    ii = g // ext[1] + lo_all[0]
    n1 = np.array([bp.n1 for bp in lat.beams])[pp]
    n2 = np.array([bp.n2 for bp in lat.beams])[pp]
    off = np.array([bp.offset for bp in lat.beams], dtype=np.int64)[pp]
    index = np.empty((len(flat), 4), dtype=np.int64)
    index[:, 0], index[:, 1], index[:, 2], index[:, 3] = ii, jj, kk, pp
    ends = np.empty((len(flat), 2), dtype=np.int64)
    ends[:, 0] = _lookup(rows_a, a, ii, jj, kk, n1)
    ends[:, 1] = _lookup(rows_b, b, ii + off[:, 0], jj + off[:, 1], kk + off[:, 2], n2)
    return index, ends


def _lookup(rows: np.ndarray, box: Region, i, j, k, n) -> np.ndarray:
    """rows[i - i0, j - j0, k - k0, n] through one linear index (faster than 4-D fancy indexing)."""
    _, nj, nk, nn = rows.shape
    return rows.reshape(-1)[(((i - box.i0) * nj + (j - box.j0)) * nk + (k - box.k0)) * nn + n]


def _power_table(s: Similarity, idx: np.ndarray) -> np.ndarray:
    """``S**i`` matrices for integer index array ``idx`` (N,), via a table over its span."""
    if idx.size == 0:
        return np.zeros((0, 4, 4))
    lo, hi = int(idx.min()), int(idx.max())
    if hi - lo + 1 <= 4 * idx.size:
        return s.power_matrices(np.arange(lo, hi + 1))[idx - lo]
    uniq, inv = np.unique(idx, return_inverse=True)
    return s.power_matrices(uniq)[inv]
