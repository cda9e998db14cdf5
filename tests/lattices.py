"""Random lattices and similarities shared by tests of several layers (importable as ``lattices``)."""

from __future__ import annotations

import numpy as np
from ple import Lattice, Rotation, Scaling, Screw, Swirl, Translation
from scipy.spatial.transform import Rotation as SciRotation


def random_similarity_matrix(rng, scale_range=(0.85, 1.15)) -> np.ndarray:
    m = np.eye(4)
    q = rng.normal(size=4)
    m[:3, :3] = rng.uniform(*scale_range) * SciRotation.from_quat(q / np.linalg.norm(q)).as_matrix()
    m[:3, 3] = rng.normal(size=3)
    return m


KINDS = ("translation", "rotation", "scaling", "screw", "swirl")


def random_similarity(rng, kind: str, step: float):
    axis = rng.normal(size=3)
    point = rng.normal(size=3) * 3 * step
    angle = rng.uniform(0.1, 0.35) * rng.choice([-1, 1])
    factor = rng.uniform(0.88, 1.12)
    if kind == "translation":
        return Translation(rng.normal(size=3) * 0.3 * step + step * np.eye(3)[rng.integers(3)])
    if kind == "rotation":
        return Rotation(angle, axis, point)
    if kind == "scaling":
        return Scaling(factor, point)
    if kind == "screw":
        return Screw(angle, axis, point, step * rng.uniform(0.5, 1.0))
    return Swirl(angle, axis, point, factor)


def random_lattice(rng, kinds, counts, step: float, radius: float, nodes: int = 2) -> Lattice:
    lat = Lattice()
    for _ in range(nodes):
        lat.add_node(rng.normal(size=3) * step * 0.4, radius * rng.uniform(0.6, 1.4))
    offsets = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, -1, 0), (0, 1, -1), (0, 0, 0)]
    for off in offsets[: 3 + rng.integers(0, 4)]:
        n1, n2 = rng.integers(0, nodes, 2)
        if off == (0, 0, 0) and n1 == n2:
            continue
        lat.add_beam(int(n1), int(n2), *off)
    lat.set_u(counts[0], random_similarity(rng, kinds[0], step))
    lat.set_v(counts[1], random_similarity(rng, kinds[1], step))
    lat.set_w(counts[2], random_similarity(rng, kinds[2], step))
    return lat


def centre_on(lat: Lattice, target: Lattice) -> None:
    """Place ``lat`` so that its mean node centre meets ``target``'s (both lattices then overlap)."""
    shift = target.evaluate().center.mean(axis=0) - lat.evaluate().center.mean(axis=0)
    lat.set_placement(Translation(shift))


def clean_centred_lattice(v_count: int, v) -> Lattice:
    """A clean lattice of two template nodes: a corner ball with three axis struts and a thinner
    centre ball joined to the eight corners around it; U a translation, W a scaling, V given."""
    lat = Lattice()
    c = lat.add_node([0, 0, 0], 0.1)
    m = lat.add_node([0.5, 0.5, 0.5], 0.06)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(c, c, *off)
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                lat.add_beam(m, c, di, dj, dk)
    lat.set_u(3, Translation([1, 0, 0]))
    lat.set_v(v_count, v)
    lat.set_w(v_count, Scaling(1.1, [0.7, 0.6, -9]))
    return lat



def two_ball_hull_volume(r1: float, r2: float, length: float) -> float:
    """The closed-form volume of the convex hull of two balls (radii r1, r2, centres ``length``
    apart): two spherical caps and the frustum between the tangent circles."""
    cos_t = (r1 - r2) / length
    sin_t = np.sqrt(1 - cos_t**2)
    rho1, rho2 = r1 * sin_t, r2 * sin_t
    h = length + (r2 - r1) * cos_t
    cap = lambda r, hh: np.pi * hh * hh * (3 * r - hh) / 3  # noqa: E731
    return float(cap(r1, r1 * (1 + cos_t)) + np.pi * h * (rho1**2 + rho1 * rho2 + rho2**2) / 3
                 + cap(r2, r2 * (1 - cos_t)))
