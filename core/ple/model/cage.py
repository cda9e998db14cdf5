"""The cage view and the frame handles of the PLE GUI (thesis §6.1.2, §6.2.2, Fig. 6.1–6.2).

The **cage** is a set of isocurves of the steady 3-map ``M(u, v, w) = G ∘ S(u, v, w) ∘ P``
with ``S(u, v, w) = W**w ∘ V**v ∘ U**u`` (§6.1.2) and real exponents: the 12 edges of the
block ``[0, nu-1] × [0, nv-1] × [0, nw-1]`` and a few interior lines. ``P`` is the centroid of
the template node-group, so at integer parameters the cage passes through group centroids.

The **frames** are the handles a designer drags (§6.2.2): the placement frame ``G`` and, in
the placement's coordinates, the frame of U, V, W: ``S ∘ B`` where ``B`` is the base frame
(unit axes at ``P``) and ``S`` is the incremental similarity (group 1) or the cumulative one
``S**(count-1)`` (the last group, §2.6.2). Moving a frame defines the similarity taking the
base frame to it (``Similarity.between_frames``, §2.5.5). All matrices are 4x4, column vectors.
"""

from __future__ import annotations

import numpy as np

from ..algebra.similarity import Similarity, Translation
from ..errors import PleError, echo
from .lattice import Lattice

AXES = ("u", "v", "w")


def cage_point(lat: Lattice) -> np.ndarray:
    """The point P of the steady 3-map: the centroid of the template node centres (3,)."""
    lat.validate()
    return lat.template_centers.mean(axis=0)


def map_points(lat: Lattice, uvw, point=None) -> np.ndarray:
    """The steady 3-map ``G ∘ W**w ∘ V**v ∘ U**u ∘ P`` (§6.1.2) at real parameters.

    ``uvw`` is (N, 3) of real (u, v, w); returns points (N, 3) in lattice coordinates.
    """
    uvw = np.asarray(uvw, dtype=float).reshape(-1, 3)
    p = cage_point(lat) if point is None else np.asarray(point, dtype=float).reshape(3)
    mu, mv, mw = (s.power_matrices(uvw[:, n]) for n, s in enumerate((lat.U, lat.V, lat.W)))
    m = lat.placement.matrix[None] @ mw @ mv @ mu
    return m[:, :3, :3] @ p + m[:, :3, 3]


def cage_curves(lat: Lattice, interior: int = 1, samples_per_group: int = 4,
                max_samples: int = 256) -> list[np.ndarray]:
    """Isocurves of the steady 3-map: polylines (s, 3), the 12 block edges first.

    Along each direction with count > 1, lines run at every pair of the other two
    parameters taken from ``interior + 2`` evenly spaced values (the two ends and
    ``interior`` inner values), so ``interior=0`` gives just the block's 12 edges.
    Each line is sampled ``samples_per_group`` times per group step (at least 2, at most
    ``max_samples`` points) so that rotating and swirling rows look round.
    """
    if interior < 0 or samples_per_group < 1 or max_samples < 2:
        raise PleError("cage: interior must be >= 0, samples_per_group >= 1, max_samples >= 2")
    spans = [c - 1 for c in lat.counts]

    def levels(span: int, inner: bool) -> np.ndarray:
        # count 1: a direction of span 0 contributes the single parameter 0
        if span == 0:
            return np.zeros(1)
        n = interior + 2 if inner else 2
        return np.linspace(0.0, span, n)

    edges, inner_lines = [], []
    for a in range(3):
        if spans[a] == 0:  # count 1: the "line" along this direction is a single point
            continue
        b, c = [x for x in range(3) if x != a]
        n = int(np.clip(samples_per_group * spans[a] + 1, 2, max_samples))
        t = np.linspace(0.0, spans[a], n)
        for x in levels(spans[b], True):
            for y in levels(spans[c], True):
                uvw = np.zeros((n, 3))
                uvw[:, a], uvw[:, b], uvw[:, c] = t, x, y
                on_edge = x in (0.0, spans[b]) and y in (0.0, spans[c])
                (edges if on_edge else inner_lines).append(uvw)
    params = edges + inner_lines
    if not params:  # a single node-group: no isocurves
        return []
    points = map_points(lat, np.concatenate(params))  # one vectorized evaluation for all curves
    return np.split(points, np.cumsum([len(p) for p in params])[:-1])


# ----- frames (§6.2.2, Fig. 6.1–6.2) ----------------------------------------------------------
def base_frame(lat: Lattice) -> np.ndarray:
    """The base frame B: unit axes at the cage point P, in lattice coordinates (4x4)."""
    m = np.eye(4)
    m[:3, 3] = cage_point(lat)
    return m


def _direction(lat: Lattice, axis: str):
    if axis not in AXES:
        raise PleError(f"frame axis must be one of u, v, w, got {echo(axis)}")
    return getattr(lat, axis)


def shows_cumulative(lat: Lattice, axis: str, cumulative: bool) -> bool:
    """Whether the frame of ``axis`` shows the cumulative similarity. Count 1 has no
    cumulative span (S**0 is the identity), so that frame always shows the incremental one."""
    return bool(cumulative) and _direction(lat, axis).count > 1


def direction_similarity(lat: Lattice, axis: str, cumulative: bool) -> Similarity:
    """Incremental similarity of ``axis`` or, if ``cumulative``, its power count-1."""
    d = _direction(lat, axis)
    if shows_cumulative(lat, axis, cumulative):
        return d.incremental ** (d.count - 1)
    return d.incremental


def direction_frame(lat: Lattice, axis: str, cumulative: bool = False) -> np.ndarray:
    """Frame of U, V or W relative to the placement frame: ``S ∘ B`` (4x4)."""
    return direction_similarity(lat, axis, cumulative).matrix @ base_frame(lat)


def direction_from_frame(lat: Lattice, axis: str, frame, cumulative: bool = False) -> Similarity:
    """The similarity taking the base frame B to ``frame`` (4x4, relative to G), §2.5.5.

    It is the incremental similarity, or the cumulative one if ``cumulative`` (and the
    count exceeds 1). Degenerate frames (sheared, unequal or zero axes, mirrored) raise
    PleError naming the frame. A linear part equal to the current one up to float32 noise
    (a frame only dragged) keeps the current one exactly (``snap_linear``)."""
    new = Similarity.between_frames(base_frame(lat), clean_frame(frame), ("the base frame", f"frame {axis.upper()}"))
    return snap_linear(new, direction_similarity(lat, axis, cumulative), cage_point(lat))


def placement_from_frame(frame, previous: Similarity | None = None) -> Similarity:
    """The placement G of a frame given as a 4x4 matrix in the rig's coordinates."""
    new = Similarity.between_frames(np.eye(4), clean_frame(frame), ("the identity frame", "frame G"))
    return new if previous is None else snap_linear(new, previous, np.zeros(3))


FLOAT32_NOISE = 1e-6  # Blender stores object matrices in float32: relative noise ~1e-7


def clean_frame(frame) -> np.ndarray:
    """A float32 frame made an exact similarity frame: its linear part replaced by the nearest
    scaled rotation (polar decomposition), the factor rounded to 1 within float32 noise (else
    a screw frame would read as a swirl about a far-away, ill-conditioned fixed point).
    Frames that are not similarities up to noise are returned as they are, to be rejected."""
    m = np.array(frame, dtype=float)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        return m
    u, sig, vt = np.linalg.svd(m[:3, :3])
    s = float(sig.mean())
    if s <= 0 or np.abs(sig - s).max() > 1e3 * FLOAT32_NOISE * s or np.linalg.det(u @ vt) < 0:
        return m
    if abs(s - 1.0) <= FLOAT32_NOISE:
        s = 1.0
    m[:3, :3] = s * (u @ vt)
    return m


def snap_linear(new: Similarity, previous: Similarity, point) -> Similarity:
    """``new`` with the linear part (factor, rotation) of ``previous`` if the two differ by
    float32 noise only, keeping where ``new`` takes ``point``; ``previous`` itself if the
    translation agrees too. A dragged translation frame thus stays an exact translation."""
    a, b = new.matrix, previous.matrix
    scale = max(1.0, float(np.abs(b[:3, :3]).max()))
    if np.abs(a[:3, :3] - b[:3, :3]).max() > FLOAT32_NOISE * scale:
        return new
    target = new.apply_points(point)
    if np.abs(target - previous.apply_points(point)).max() <= FLOAT32_NOISE * max(1.0, float(np.abs(target).max())):
        return previous
    if previous.factor == 1.0 and previous.angle == 0.0:  # pure translation: no axis to re-derive
        return Translation(target - np.asarray(point, dtype=float))
    m = b.copy()
    m[:3, 3] = target - b[:3, :3] @ np.asarray(point, dtype=float)
    return Similarity.from_matrix(m, "frame")
