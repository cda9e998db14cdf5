"""Ball-and-beam preview meshes (not watertight: overlapping spheres and frusta).

Vectorized instancing: one template sphere and one template frustum ring, placed per
ball and per beam with numpy, so a 10⁵-beam preview builds in well under a second.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..algebra.vectors import perpendicular_frames

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh


def balls_beams_mesh(center: np.ndarray, radius: np.ndarray, beam_nodes: np.ndarray,
                     sphere_subdivisions: int = 1, segments: int = 8,
                     beam_scale: float = 1.0) -> trimesh.Trimesh:
    """Preview mesh: an icosphere per ball (centres (N, 3), radii (N,)) and a frustum per
    beam (beam_nodes (M, 2) rows into the ball arrays), radii scaled by ``beam_scale``."""
    import trimesh
    sphere = trimesh.creation.icosphere(subdivisions=sphere_subdivisions)
    sv, sf = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    verts = (sv[None] * radius[:, None, None] + center[:, None]).reshape(-1, 3)
    faces = (sf[None] + (np.arange(len(center)) * len(sv))[:, None, None]).reshape(-1, 3)
    parts_v, parts_f, offset = [verts], [faces], len(verts)
    # a beam between coincident balls has no direction (and nothing to draw)
    beam_nodes = beam_nodes[np.linalg.norm(center[beam_nodes[:, 1]] - center[beam_nodes[:, 0]], axis=1) > 0]
    if len(beam_nodes):
        a, b = center[beam_nodes[:, 0]], center[beam_nodes[:, 1]]
        ra, rb = radius[beam_nodes[:, 0]] * beam_scale, radius[beam_nodes[:, 1]] * beam_scale
        d = b - a
        length = np.linalg.norm(d, axis=1, keepdims=True)
        axis = d / np.where(length > 0, length, 1.0)
        e1, e2 = perpendicular_frames(axis)
        t = np.linspace(0, 2 * np.pi, segments, endpoint=False)
        ring = np.cos(t)[None, :, None] * e1[:, None] + np.sin(t)[None, :, None] * e2[:, None]  # (M, s, 3)
        bottom = a[:, None] + ring * ra[:, None, None]
        top = b[:, None] + ring * rb[:, None, None]
        bv = np.concatenate([bottom, top], axis=1).reshape(-1, 3)
        s = np.arange(segments)
        n = (s + 1) % segments
        quad = np.stack([np.stack([s, n, n + segments], 1), np.stack([s, n + segments, s + segments], 1)], 1)
        quad = quad.reshape(-1, 3)
        bf = quad[None] + (np.arange(len(a)) * 2 * segments)[:, None, None] + offset
        parts_v.append(bv)
        parts_f.append(bf.reshape(-1, 3))
    return trimesh.Trimesh(np.concatenate(parts_v), np.concatenate(parts_f), process=False)


def hull_rows(node_index: np.ndarray, beam_nodes: np.ndarray, limit: int):
    """A level of detail of a drawn region for at most ``limit`` balls and beams: the nodes of the
    node-groups on the six faces of its index box (what is seen from outside) and the beams
    between them, or every k-th of those nodes alone when even that is more. Returns (node rows,
    beam rows, the kept beams' ends renumbered to the kept nodes)."""
    g = np.asarray(node_index)[:, :3]
    if not len(g):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2), np.int64)
    keep = np.flatnonzero(((g == g.min(axis=0)) | (g == g.max(axis=0))).any(axis=1))
    row = np.full(len(g), -1, np.int64)
    row[keep] = np.arange(len(keep))
    beams = np.flatnonzero((row[beam_nodes] >= 0).all(axis=1)) if len(beam_nodes) else np.zeros(0, np.int64)
    if len(keep) + len(beams) > limit:  # balls alone, thinned
        keep, beams = keep[::-(-len(keep) // max(limit, 1))], beams[:0]
        row[:] = -1
        row[keep] = np.arange(len(keep))
    return keep, beams, row[beam_nodes[beams]].reshape(-1, 2)
