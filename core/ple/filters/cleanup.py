"""Cleanup after trimming: dangling beams and floating pieces.

Trimming a lattice to a body leaves balls hanging by one beam (or none) and pieces that no
longer touch the rest. ``cleanup_evaluation`` removes, round after round, every ball of degree
≤ 1 with its beam (what is left is the 2-core of the beam graph), then keeps only the largest
connected component (by balls). ``cleanup`` turns the result into a filter of the lattice (the
surviving node indices), so every door (eval, mesh, info, queries) sees the cleaned lattice.

With a skin of thickness t (``skin=t``), beams that end on the skin are kept: a ball that
reaches into the shell {x in the body : sd(x) < t} is anchored (never peeled: the skin holds
it), and every piece touching the skin is one piece with it (the skin joins them) when the
largest is chosen.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import PleError, echo
from ..model.lattice import Evaluation, Lattice
from .base import Filter
from .body import Body, body_of

MAX_CLEANUP_NODES = 50_000_000  # the graph is built in memory: about 60 bytes per node and beam


@dataclass
class CleanupReport:
    """What the cleanup removed and kept."""

    rounds: int  # peeling rounds that removed something
    dangling_nodes: int  # balls of degree <= 1 removed (over all rounds)
    dangling_beams: int  # beams removed with them
    components: int  # connected components before keeping the largest
    dropped_nodes: int  # balls of the dropped components
    dropped_beams: int
    nodes: int  # kept
    beams: int
    anchored: int = 0  # kept balls held by the skin (with a skin only)

    def as_dict(self) -> dict:
        return asdict(self)

    def __str__(self) -> str:
        return (f"cleanup: removed {self.dangling_nodes:,} dangling balls and {self.dangling_beams:,} beams in "
                f"{self.rounds} rounds; dropped {self.components - 1 if self.components else 0} of "
                f"{self.components} components ({self.dropped_nodes:,} balls, {self.dropped_beams:,} beams); "
                f"kept {self.nodes:,} balls and {self.beams:,} beams"
                + (f" ({self.anchored:,} balls held by the skin)" if self.anchored else ""))


def skin_anchored(body: Body, thickness: float, center, radius) -> np.ndarray:
    """bool (N,): which balls reach into the skin of ``body`` (the shell of points inside it
    closer than ``thickness`` to its surface). A ball whose centre lies at depth d inside meets
    the shell when d < r + t (the distance from the centre to the shell is d - t); a ball whose
    centre is outside meets it when it touches the body (d < r)."""
    if not thickness > 0:
        raise PleError(f"cleanup: skin thickness must be positive, got {echo(thickness)}")
    c = np.asarray(center, dtype=float).reshape(-1, 3)
    r = np.asarray(radius, dtype=float).reshape(-1)
    inside = body.contains(c)
    out = np.zeros(len(c), dtype=bool)
    out[inside] = body.near(c[inside], r[inside] + thickness)
    out[~inside] = body.near(c[~inside], r[~inside])
    return out


def cleanup_evaluation(ev: Evaluation, largest: bool = True,
                       anchored: np.ndarray | None = None) -> tuple[Evaluation, CleanupReport]:
    """``ev`` without dangling balls (degree <= 1, removed round by round) and, with ``largest``,
    without the components other than the largest (ties: the one holding the lowest row).

    ``anchored`` (bool per node, e.g. ``skin_anchored``) marks balls held by a skin: they are
    never peeled, and all pieces holding one count as one piece (joined through the skin)."""
    n = len(ev.node_index)
    ends = np.asarray(ev.beam_nodes, dtype=np.int64).reshape(-1, 2)
    held = np.zeros(n, dtype=bool) if anchored is None else np.asarray(anchored, dtype=bool).reshape(-1)
    if len(held) != n:
        raise PleError(f"cleanup: {len(held)} anchor flags for {n} nodes")
    alive = np.ones(n, dtype=bool)
    beam_alive = np.ones(len(ends), dtype=bool)
    deg = np.bincount(ends.reshape(-1), minlength=n)
    rounds = 0
    while True:
        drop = alive & (deg <= 1) & ~held
        if not drop.any():
            break
        rounds += 1
        alive &= ~drop
        dying = beam_alive & (drop[ends[:, 0]] | drop[ends[:, 1]])
        beam_alive &= ~dying
        deg -= np.bincount(ends[dying].reshape(-1), minlength=n)
    dangling_nodes, dangling_beams = n - int(alive.sum()), len(ends) - int(beam_alive.sum())
    components = dropped_nodes = dropped_beams = 0
    if alive.any():
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        e = ends[beam_alive]
        skin = np.flatnonzero(held & alive)  # joined through one extra vertex: the skin (row n)
        e = np.concatenate([e, np.stack([skin, np.full(len(skin), n)], axis=1)])
        graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n + 1, n + 1))
        _, label = connected_components(graph, directed=False)
        label = label[:n]
        rows = np.flatnonzero(alive)
        uniq, inv, sizes = np.unique(label[rows], return_inverse=True, return_counts=True)
        components = len(uniq)
        if largest and components > 1:
            keep_label = uniq[np.argmax(sizes)]  # argmax takes the first: the component of the lowest row
            gone = alive & (label != keep_label)
            dropped_nodes = int(gone.sum())
            dying = beam_alive & gone[ends[:, 0]]
            dropped_beams = int(dying.sum())
            alive &= ~gone
    out = ev.select(alive)
    report = CleanupReport(rounds, dangling_nodes, dangling_beams, components, dropped_nodes, dropped_beams,
                           len(out.node_index), len(out.beam_nodes), int((held & alive).sum()))
    return out, report


class NodeSet(Filter):
    """Keeps exactly the nodes whose (i, j, k, n) are listed (a computed selection, such as a
    cleanup's survivors); not data: it is not written into ``ple-lattice/1``."""

    def __init__(self, lat: Lattice, node_index) -> None:
        idx = np.asarray(node_index, dtype=np.int64).reshape(-1, 4)
        self._shape = (*lat.counts, len(lat.nodes))
        self.keys = np.unique(self._key(idx))

    def _key(self, idx: np.ndarray) -> np.ndarray:
        _, nv, nw, nn = self._shape
        return ((idx[:, 0] * nv + idx[:, 1]) * nw + idx[:, 2]) * nn + idx[:, 3]

    def node_mask(self, lat, node_index, center, radius):
        k = self._key(np.asarray(node_index, dtype=np.int64).reshape(-1, 4))
        pos = np.clip(np.searchsorted(self.keys, k), 0, max(len(self.keys) - 1, 0))
        return self.keys[pos] == k if len(self.keys) else np.zeros(len(k), dtype=bool)


class Cleanup(Filter):
    """A cleanup as data (``{"cleanup": {"filter": F, "largest": true, "skin": T}}``): keeps the
    nodes that survive the cleanup of what ``part`` keeps of the whole lattice (no part: every
    node). The survivors are computed once per lattice program (the lattice being filtered,
    without its filter) and reused by every evaluation of it; ``report`` is the last cleanup's."""

    def __init__(self, part: Filter | None = None, largest: bool = True, skin: float | None = None) -> None:
        if part is not None and not isinstance(part, Filter):
            raise PleError(f"a cleanup needs a filter, got {type(part).__name__}")
        if skin is not None and not skin > 0:
            raise PleError(f"cleanup: skin thickness must be positive, got {echo(skin)}")
        self.part, self.largest, self.skin = part, bool(largest), skin
        self.report: CleanupReport | None = None
        self._cache: tuple | None = None

    @staticmethod
    def _program(lat: Lattice) -> tuple:
        """What the survivors depend on: the template, counts and the objects placing and grading it."""
        return ((lat.counts, lat.template_centers.tobytes(), lat.template_radii.tobytes(), tuple(lat.beams)),
                (lat.u, lat.v, lat.w, lat.placement, lat.becots, lat.group_map, lat.radius_field))

    def survivors(self, lat: Lattice) -> NodeSet:
        key = self._program(lat)
        if self._cache is None or self._cache[0][0] != key[0] or any(
                a is not b for a, b in zip(self._cache[0][1], key[1])):
            base = lat.unfiltered().with_filter(self.part)
            if base.node_count() > MAX_CLEANUP_NODES:
                raise PleError(f"cleanup of {base.node_count():,} nodes (limit {MAX_CLEANUP_NODES:,})")
            ev = base.evaluate()
            anchored = None
            if self.skin is not None:
                anchored = skin_anchored(body_of(base, "cleanup with a skin"), self.skin, ev.center, ev.radius)
            out, self.report = cleanup_evaluation(ev, self.largest, anchored)
            self._cache = (key, NodeSet(lat, out.node_index))
        return self._cache[1]

    def node_mask(self, lat, node_index, center, radius):
        return self.survivors(lat).node_mask(lat, node_index, center, radius)

    def __repr__(self) -> str:
        return f"Cleanup({self.part!r}, largest={self.largest}, skin={self.skin})"


def cleanup(lat: Lattice, region=None, largest: bool = True,
            skin: float | None = None) -> tuple[Lattice, CleanupReport]:
    """``lat`` restricted to the cleaned evaluation of ``region`` (default: all of it). With
    ``skin`` (a thickness), beams ending on the skin of the lattice's body are kept. Of the whole
    lattice, the result is a :class:`Cleanup` of the lattice's filter (data: ``ple ir`` writes it);
    of a smaller region, the surviving nodes (a ``NodeSet``)."""
    r = lat.region(region)
    if r == lat.region():
        f = Cleanup(lat.filter, largest, skin)
        out = lat.unfiltered().with_filter(f)
        f.survivors(out)
        return out, f.report
    if lat.node_count(r) > MAX_CLEANUP_NODES:
        raise PleError(f"cleanup of {lat.node_count(r):,} nodes (limit {MAX_CLEANUP_NODES:,}): give a smaller --region")
    ev = lat.evaluate(r)
    anchored = None
    if skin is not None:
        anchored = skin_anchored(body_of(lat, "cleanup with a skin"), skin, ev.center, ev.radius)
    ev, report = cleanup_evaluation(ev, largest, anchored)
    return lat.with_filter(NodeSet(lat, ev.node_index)), report
