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


def test_hull_rows_keep_the_groups_on_the_region_faces_and_the_beams_between_them():
    import ple
    from ple.meshing.preview import hull_rows

    lat = ple.load_lattice("fig6_3")  # two nodes a group, beams to neighbours and diagonals
    ev = lat.evaluate("1:6,2:5,0:4")
    keep, beams, ends = hull_rows(ev.node_index, ev.beam_nodes, 10**9)
    # independent: a node is on the hull when one of its i, j, k is at the region's first or last
    on = [any(x in (lo, hi - 1) for x, lo, hi in zip(n[:3], (1, 2, 0), (6, 5, 4))) for n in ev.node_index]
    assert keep.tolist() == [r for r, o in enumerate(on) if o]
    assert beams.tolist() == [m for m, (a, b) in enumerate(ev.beam_nodes) if on[a] and on[b]]
    assert np.array_equal(keep[ends], ev.beam_nodes[beams])  # the ends name the same nodes
    inner = ev.node_index[:, :3]
    assert not set(map(tuple, inner[keep])) & {(3, 3, 1), (4, 3, 2)}  # interior groups are not drawn
    # fewer allowed than the hull holds: every k-th hull node alone, at most the limit
    k2, b2, e2 = hull_rows(ev.node_index, ev.beam_nodes, 20)
    assert 0 < len(k2) <= 20 and set(k2) <= set(keep) and len(b2) == len(e2) == 0
    empty = hull_rows(np.zeros((0, 4), np.int64), np.zeros((0, 2), np.int64), 5)
    assert all(len(x) == 0 for x in empty)
