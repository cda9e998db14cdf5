"""RangeFinder for Möbius steady lattices: BIQ and PMC through the pre-image under a sphere inversion.

Thesis §11.2.1: a Möbius steady pattern with a fixed point F is a similarity steady pattern seen
through a circle inversion R centred at F; in 3D the Poincaré extensions act (R is the inversion
in the sphere of centre (F, 0), §11.5), and S = R ∘ U ∘ R is a similarity. When U, V and W (the
directions with more than one group) share a fixed point F and commute, as in every Möbius
1-pattern and every TMI lattice (§11.4: U and V commute, a circle inversion of a COTS map),

    R(W**k ∘ V**j ∘ U**i ∘ G (B)) = S_W**k ∘ S_V**j ∘ S_U**i (R ∘ G (B)),

so the images of the nodes under R form a steady *similarity* lattice of balls (the pre-image
lattice), which the regular RangeFinder (§7) queries. R is a bijection of extended space that
maps a ball not containing F to a ball, so a query ball Q meets a node exactly when R(Q) meets
its pre-image: exact for nodes.

Beams are straight cone-beams between the mapped balls, not steady (§11.3). §11.3 conjectures
bounding them by a Möbius steady pattern of balls that R turns into a similarity steady pattern;
this does it. A cone-beam lies in every ball holding its two end balls. Let E_p be the smallest
ball holding the pre-images of pattern p's end balls in group 0, R∘G(B_a) and S_d(R∘G(B_b)) with
S_d = S_W**dk ∘ S_V**dj ∘ S_U**di. As the S commute, S_g(E_p) holds group g's two end-ball
pre-images, and where S_g(E_p) does not contain R(∞) = F, R(S_g(E_p)) is a world ball holding
both end balls, hence the beam. A query meeting the beam then meets S_g(E_p) in the pre-image.
The bounds that contain F are found once per lattice (a point query at F on the pre-image
lattice) and their beams are candidates of every query. Queries whose ball contains F (R maps
them to the outside of a ball) are left to the naive path. Candidates are tested exactly against
the lattice's own balls and beams, so the hits equal the naive path's.

Lattices whose directions share no fixed point or do not commute (a general Möbius-frame
2-pattern) have no such pre-image: ``plan(lat).reason`` says why and the naive path answers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..algebra.elements import ball_ball_interfere, ball_beam_interfere, enclosing_ball
from ..algebra.mobius import Cline, Mobius, map_balls
from ..algebra.similarity import Similarity
from ..model.lattice import Lattice
from ..model.mobius import MobiusGroups
from .plans import cached
from .rangefinder import lattice_hits as similarity_hits

FIXED_TOL = 1e-9  # |X(F) - F| relative to 1 + |F|: F is a fixed point of X
COMMUTE_TOL = 1e-9  # of normalized matrices
MARGIN = 1e-9  # relative widening of pre-image queries and bounds: rounding never loses a candidate


@dataclass
class MobiusPlan:
    """The pre-image lattice of a Möbius lattice, or why it has none (``pre`` None, ``reason``).

    ``pre`` holds the node pre-images (template nodes 0..nn-1) and the beam bounds E_p (nodes
    nn + p); ``center`` (3,) is the inversion's centre (F, 0) and ``rho2`` its squared radius
    (None: U, V, W are similarities, no inversion); ``always`` (m, 4) [i, j, k, p] are the beams
    whose bound contains F."""

    pre: Lattice | None
    reason: str = ""
    center: np.ndarray | None = None
    rho2: float = 1.0
    always: np.ndarray | None = None


def _active(gm: MobiusGroups, counts) -> list[Mobius]:
    ident = Mobius.identity()
    return [g for g, n in zip((gm.u, gm.v, gm.w), counts) if n > 1 and not g.allclose(ident, 1e-15)]


def _fixes(g: Mobius, f: complex) -> bool:
    return abs(complex(g(np.array([f]))[0]) - f) <= FIXED_TOL * (1 + abs(f))


def _commute(a: Mobius, b: Mobius) -> bool:
    return (a @ b).allclose(b @ a, COMMUTE_TOL)


def invert_balls(center: np.ndarray, rho2: float, c: np.ndarray, r: np.ndarray):
    """Images of balls (c (N, 3), r (N,)) under the inversion in the sphere (center, sqrt(rho2)):
    balls (c', r') and the margin |c - center|² - r² (> 0: the ball does not contain the centre)."""
    rel = c - center
    den = np.sum(rel * rel, axis=-1) - r * r
    safe = np.where(den > 0, den, 1.0)
    return center + rho2 * rel / safe[:, None], rho2 * r / safe, den


def _similarity(g: Mobius, mr: np.ndarray | None) -> Similarity:
    """S = R ∘ g ∘ R as a Similarity (g itself when there is no inversion)."""
    if mr is None:
        return g.to_similarity()
    s = mr @ g.m.conj() @ mr.conj()
    s = s / np.sqrt(s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0])
    return Mobius(np.array([[s[0, 0], s[0, 1]], [0, s[1, 1]]], dtype=complex)).to_similarity()


def _ball(s: Similarity, c: np.ndarray, r: np.ndarray):
    return s.apply_points(c), r * s.factor


def _pre_lattice(lat: Lattice, gm: MobiusGroups, mr, center, rho2):
    """The pre-image lattice (nodes then beam bounds), or None when a template ball contains F."""
    nn = len(lat.nodes)
    c, r = map_balls(np.broadcast_to(gm.frame.m, (nn, 2, 2)), lat.template_centers, lat.template_radii)
    if center is not None:
        c, r, den = invert_balls(center, rho2, c, r)
        if np.any(den <= 1e-9 * np.sum((c - center) ** 2, axis=-1)):
            return None
    su, sv, sw = (_similarity(g, mr) if n > 1 else Similarity()  # a direction of one group never moves
                  for g, n in zip((gm.u, gm.v, gm.w), lat.counts))
    pre = Lattice()
    for q in range(nn):
        pre.add_node(c[q], float(r[q]))
    for b in lat.beams:
        move = (sw ** b.dk) @ (sv ** b.dj) @ (su ** b.di)
        cb, rb = _ball(move, c[b.n2][None], r[b.n2][None])
        ec, er = enclosing_ball(c[b.n1], r[b.n1], cb[0], rb[0])
        pre.add_node(ec, float(er) * (1 + MARGIN) + MARGIN * float(np.linalg.norm(ec)))
    nu, nv, nw = lat.counts
    pre.set_u(nu, su)
    pre.set_v(nv, sv)
    pre.set_w(nw, sw)
    return pre


def plan(lat: Lattice) -> MobiusPlan:
    """The pre-image lattice of ``lat`` (a Möbius lattice), built once (see module doc)."""
    gm = lat.group_map
    if not isinstance(gm, MobiusGroups):
        return MobiusPlan(None, f"a {getattr(gm, 'kind', 'steady')} lattice is not a Möbius lattice")
    if lat.groups == 1:
        return MobiusPlan(None, "one group")
    act = _active(gm, lat.counts)
    if any(not _commute(a, b) for n, a in enumerate(act) for b in act[n + 1:]):
        return MobiusPlan(None, "U, V, W do not commute (§11.3)")
    if all(g.is_similarity for g in act):  # similarities (∞ fixed): no inversion needed
        pre = _pre_lattice(lat, gm, None, None, 1.0)
        return MobiusPlan(pre, always=np.zeros((0, 4), np.int64))
    moving = next(g for g in act if not g.is_similarity)
    nn = len(lat.nodes)
    fc, _ = map_balls(np.broadcast_to(gm.frame.m, (nn, 2, 2)), lat.template_centers, lat.template_radii)
    for f in moving.fixed_points():
        if not (math.isfinite(f.real) and math.isfinite(f.imag)) or not all(_fixes(g, f) for g in act):
            continue
        center = np.array([f.real, f.imag, 0.0])
        rho = float(np.max(np.linalg.norm(fc - center, axis=1))) or 1.0
        mr = Cline.circle(f, rho).antiholomorphic()
        pre = _pre_lattice(lat, gm, mr, center, rho * rho)
        if pre is None:
            continue
        reach = MARGIN * (1 + float(np.linalg.norm(center)))
        nh, _, _ = similarity_hits(pre, center[None], np.array([reach]))
        hits = nh[nh[:, 4] >= nn]
        always = np.concatenate([hits[:, 1:4], hits[:, 4:] - nn], axis=1)
        return MobiusPlan(pre, center=center, rho2=rho * rho, always=always)
    return MobiusPlan(None, "U, V, W share no fixed point (§11.2.1)")


def cached_plan(lat: Lattice) -> MobiusPlan:
    return cached(lat, "mobius", plan)


def lattice_hits(lat: Lattice, c: np.ndarray, r: np.ndarray, pl: MobiusPlan):
    """Möbius RangeFinder BIQ: (node hits (N, 5), beam hits (M, 5), rest, path), hits as
    (qid, i, j, k, x); ``path`` is the pre-image RangeFinder's (§7.3.1: "1", "u" or "uv");
    ``rest`` (q,) bool marks the queries whose ball contains the inversion centre F, which the
    caller answers by the naive path (their pre-image is the outside of a ball)."""
    nn = len(lat.nodes)
    rest = np.zeros(len(c), bool)
    if pl.center is None:
        qc, qr = c, r * (1 + MARGIN) + MARGIN * np.linalg.norm(c, axis=1)
    else:
        qc, qr, den = invert_balls(pl.center, pl.rho2, c, r)
        gap = np.linalg.norm(c - pl.center, axis=1) - r
        rest = (den <= 0) | (gap <= 1e-9 * (np.linalg.norm(c, axis=1) + r + np.linalg.norm(pl.center)))
        # a world gap of ε |x| maps to about ε |x| / |x - F| relative to the pre-image's distance from F
        world = (np.linalg.norm(c, axis=1) + r + np.linalg.norm(pl.center)) / np.where(rest, 1.0, gap)
        qr = qr + MARGIN * (qr + np.linalg.norm(qc, axis=1)) * (1 + world)
    keep = np.flatnonzero(~rest)
    nh, _, path = similarity_hits(pl.pre, qc[keep], qr[keep])
    nh[:, 0] = keep[nh[:, 0]]
    nodes = nh[nh[:, 4] < nn]
    beams = nh[nh[:, 4] >= nn]
    beams[:, 4] -= nn
    if len(pl.always) and len(keep):
        extra = np.concatenate([np.repeat(keep, len(pl.always))[:, None], np.tile(pl.always, (len(keep), 1))], axis=1)
        beams = np.unique(np.concatenate([beams, extra]), axis=0)
    return exact_hits(lat, nodes, c, r), exact_beam_hits(lat, beams, c, r), rest, path


def exact_hits(lat: Lattice, cand: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Node candidates (qid, i, j, k, n) that truly meet their query, tested on the lattice's balls."""
    if not len(cand):
        return cand
    nc, nr = lat.node_balls(cand[:, 1:])
    return cand[ball_ball_interfere(c[cand[:, 0]], r[cand[:, 0]], nc, nr)]


def exact_beam_hits(lat: Lattice, cand: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Beam candidates (qid, i, j, k, p) whose beam exists and meets its query (exact)."""
    if not len(cand):
        return np.zeros((0, 5), np.int64)
    pats = np.array([(b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams], dtype=np.int64)[cand[:, 4]]
    to = cand[:, 1:4] + pats[:, 2:]
    cand, pats, to = (x[np.all((to >= 0) & (to < lat.counts), axis=1)] for x in (cand, pats, to))
    ca, ra = lat.node_balls(np.concatenate([cand[:, 1:4], pats[:, :1]], axis=1))
    cb, rb = lat.node_balls(np.concatenate([to, pats[:, 1:2]], axis=1))
    return cand[ball_beam_interfere(c[cand[:, 0]], r[cand[:, 0]], ca, ra, cb, rb)]
