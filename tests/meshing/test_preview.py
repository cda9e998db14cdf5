"""Balls-and-beams preview meshes: every ball is an icosphere on its sphere, every beam a frustum
whose end rings lie on circles of the end radii around the beam axis."""

from __future__ import annotations

import numpy as np
import trimesh
from ple.meshing.preview import balls_beams_mesh


def test_preview_places_spheres_and_frusta(rng):
    center = rng.random((5, 3)) * 4
    radius = 0.1 + 0.2 * rng.random(5)
    beams = np.array([[0, 1], [1, 2], [3, 4], [0, 4]])
    seg = 8
    mesh = balls_beams_mesh(center, radius, beams, sphere_subdivisions=1, segments=seg)
    ico = trimesh.creation.icosphere(subdivisions=1)
    nv, nf = len(ico.vertices), len(ico.faces)
    assert len(mesh.faces) == 5 * nf + len(beams) * 2 * seg
    v = np.asarray(mesh.vertices)
    balls = v[:5 * nv].reshape(5, nv, 3)
    assert np.allclose(np.linalg.norm(balls - center[:, None], axis=2), radius[:, None])
    rings = v[5 * nv:].reshape(len(beams), 2, seg, 3)
    for (a, b), ring in zip(beams, rings):
        axis = (center[b] - center[a]) / np.linalg.norm(center[b] - center[a])
        for end, node in ((0, a), (1, b)):
            off = ring[end] - center[node]
            assert np.allclose(off @ axis, 0.0, atol=1e-12)  # the ring is perpendicular to the beam
            assert np.allclose(np.linalg.norm(off, axis=1), radius[node])


def test_beams_between_coincident_balls_are_skipped():
    c = np.array([[0.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0]])
    mesh = balls_beams_mesh(c, np.full(3, 0.1), np.array([[0, 1], [1, 2]]), segments=6)
    ico = trimesh.creation.icosphere(subdivisions=1)
    assert len(mesh.faces) == 3 * len(ico.faces) + 1 * 2 * 6
    assert np.all(np.isfinite(mesh.vertices))
