"""Skins: a shell of thickness t inside a body, united with the lattice that fills it.

The shell is the body minus its inward offset {x : sd(x) ≥ t}, where sd is the body's exact
signed distance (positive inside) sampled on a grid and interpolated trilinearly; the offset
surface is extracted by manifold3d's level set (marching tetrahedra on a body-centred grid) and
every Boolean is manifold3d's, so the result is one watertight solid. The lattice's own mesh
is clipped to the body (beams trimmed by ``any`` are cut at the surface) before the union.

Clipping is also how every mesh of a lattice filled by ``any`` ends at the body's surface
(``clip_bodies``, ``clip_to_bodies``; ``ple.meshing.tessellate`` applies them): the balls that
touch the body from outside and the beams that cross its surface are cut there, by one
manifold3d intersection of the closed lattice mesh with each body.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from ..errors import PleError
from ..filters.body import Body, body_filters
from .weld import COLLAPSE_GRIDS, grid_spacing

MAX_SDF_SAMPLES = 8_000_000  # grid samples of the signed distance


def _manifold(vertices, faces):
    from manifold3d import Manifold, Mesh  # optional: only skins need manifold3d

    m = Manifold(Mesh(vert_properties=np.asarray(vertices, dtype=np.float32),
                      tri_verts=np.asarray(faces, dtype=np.uint32)))
    if m.status().name != "NoError":
        raise PleError(f"the mesh is not a closed manifold for Booleans ({m.status().name})")
    return m


def _trimesh(m, frame: tuple | None = None) -> trimesh.Trimesh:
    """The Boolean's result with its slivers (features under a few float32 steps at its size,
    which a float32 file cannot keep apart) removed by manifold3d itself: it stays manifold.
    ``frame`` (centre, scale): the Boolean ran in that scaled frame (``body_frame``); the slivers
    are measured and the result returned in world coordinates."""
    c, s = frame if frame is not None else (np.zeros(3), 1.0)
    if not m.is_empty():
        box = np.asarray(m.bounding_box(), float)
        m = m.simplify(COLLAPSE_GRIDS * grid_spacing(box[:3] * s + c, box[3:] * s + c) / s)
    mesh = m.to_mesh()
    v = np.asarray(mesh.vert_properties, float)[:, :3] * s + c
    return trimesh.Trimesh(v, np.asarray(mesh.tri_verts), process=False)


def body_frame(bodies) -> tuple[np.ndarray, float]:
    """(centre, scale) of a frame in which the bodies span about 1: manifold3d computes in
    float32, whose products overflow or lose the mesh at sizes like 1e30 (or 4e10 beside a
    radius of 1); a Boolean in this frame keeps the right cells at any size."""
    lo = np.min([b.lo for b in bodies], axis=0)
    hi = np.max([b.hi for b in bodies], axis=0)
    return (lo + hi) / 2, float((hi - lo).max()) or 1.0


def inward_offset(body: Body, thickness: float, edge: float | None = None):
    """The manifold {x : sd(x) ≥ thickness} (empty when the body is thinner than 2·thickness)."""
    from manifold3d import Manifold

    if not thickness > 0:
        raise PleError(f"skin thickness must be positive, got {thickness!r}")
    edge = float(edge or thickness / 2)
    g = edge / 2  # samples twice as fine as the level set's grid
    lo, hi = body.lo - 2 * edge, body.hi + 2 * edge
    samples = float(np.prod(np.ceil((hi - lo) / g) + 2))  # as a float: no integer overflow at tiny edges
    if not samples <= MAX_SDF_SAMPLES:
        raise PleError(f"skin: {samples:,.3g} distance samples at edge length {edge:g} "
                       f"(limit {MAX_SDF_SAMPLES:,}); use a coarser edge length")
    dims = np.ceil((hi - lo) / g).astype(int) + 2
    axes = [lo[a] + g * np.arange(dims[a]) for a in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    sd = _band_signed_distance(body, pts, thickness - 2 * g, thickness + 2 * g, g)
    table = sd.reshape(tuple(dims)).tolist()
    nx, ny, nz = (int(d) - 2 for d in dims)
    x0, y0, z0 = (float(v) for v in lo)

    def sdf(x: float, y: float, z: float) -> float:  # trilinear interpolation of the samples
        fx, fy, fz = (x - x0) / g, (y - y0) / g, (z - z0) / g
        i, j, k = min(max(int(math.floor(fx)), 0), nx), min(max(int(math.floor(fy)), 0), ny), \
            min(max(int(math.floor(fz)), 0), nz)
        u, v, w = fx - i, fy - j, fz - k
        a, b = table[i], table[i + 1]
        c00 = a[j][k] * (1 - u) + b[j][k] * u
        c01 = a[j][k + 1] * (1 - u) + b[j][k + 1] * u
        c10 = a[j + 1][k] * (1 - u) + b[j + 1][k] * u
        c11 = a[j + 1][k + 1] * (1 - u) + b[j + 1][k + 1] * u
        return (c00 * (1 - v) + c10 * v) * (1 - w) + (c01 * (1 - v) + c11 * v) * w

    return Manifold.level_set(sdf, [*map(float, lo), *map(float, hi)], edge, float(thickness))


def _surface_samples(body: Body, spacing: float) -> np.ndarray:
    """Points on every face, at most ``spacing`` apart along its edges: every surface point lies
    within ``spacing`` of one (a point of a triangle is within its longest edge of each corner)."""
    tri = body.triangles
    longest = np.max(np.linalg.norm(tri - tri[:, [1, 2, 0]], axis=2), axis=1)
    out = [body.vertices]
    for n in np.unique(np.ceil(longest / spacing).astype(int)):
        if n < 2:
            continue
        sel = tri[np.ceil(longest / spacing).astype(int) == n]
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        a, b = i[keep] / n, j[keep] / n
        w = np.stack([1 - a - b, a, b], axis=1)  # barycentric grid of the n-fold subdivision
        out.append(np.einsum("sk,tkd->tsd", w, sel).reshape(-1, 3))
    return np.concatenate(out)


def _band_signed_distance(body: Body, pts: np.ndarray, low: float, high: float, spacing: float) -> np.ndarray:
    """Signed distances (inside positive) clamped to [low, high] inside the body and -high outside:
    exact in the band where it matters; elsewhere bounded by the distance to surface samples
    (a KD-tree query), which is at most ``spacing`` above the true distance."""
    from scipy.spatial import cKDTree  # optional: only skins need it

    inside = body.contains(pts)
    ds, _ = cKDTree(_surface_samples(body, spacing)).query(pts, distance_upper_bound=high + spacing)
    out = np.where(inside, np.where(ds < low, low, high), -high)  # d <= ds < low, or d >= ds - spacing > high
    band = np.flatnonzero(inside & (ds >= low) & (ds - spacing <= high))
    for s in range(0, len(band), 1 << 18):
        rows = band[s:s + (1 << 18)]
        out[rows] = np.clip(body.distance(pts[rows], high), low, high)
    return out


def skin(body: Body, thickness: float, lattice_mesh=None, edge: float | None = None) -> trimesh.Trimesh:
    """The shell of ``body`` of the given thickness, united with ``lattice_mesh`` (a closed
    trimesh, clipped to the body) when given: one watertight solid."""
    if not body.closed:
        raise PleError("skin: the body must be a closed mesh")
    outer = _manifold(body.vertices, body.faces)
    solid = outer - inward_offset(body, thickness, edge)
    if lattice_mesh is not None and len(lattice_mesh.faces):
        lattice = _manifold(lattice_mesh.vertices, lattice_mesh.faces)
        if not any(b is body for b in lattice_mesh.metadata.get("ple_cut_by", ())):
            lattice = lattice ^ outer  # not cut yet (cutting twice would meet coincident faces)
        solid = solid + lattice
    return _trimesh(solid)


def clip_bodies(lat) -> list[Body]:
    """The bodies a lattice's mesh is cut at: those of its ``any`` body filters (reached through
    and-compounds: ``ple.filters.body.body_filters``)."""
    return [f.body for f in body_filters(lat) if f.mode == "any"]


def clip_to_bodies(mesh: trimesh.Trimesh, bodies) -> trimesh.Trimesh:
    """``mesh`` (closed) intersected with every body (closed): what sticks out is cut at their
    surfaces. One watertight solid; an empty mesh stays empty."""
    if not bodies or not len(mesh.faces):
        return mesh
    for body in bodies:
        if not body.closed:
            raise PleError(f"{body.name}: an open body (winding-number fallback) cannot cut a mesh: close it")
    c, s = body_frame(bodies)
    solid = _manifold((np.asarray(mesh.vertices) - c) / s, mesh.faces)
    for body in bodies:
        solid = solid ^ _manifold((body.vertices - c) / s, body.faces)
    out = _trimesh(solid, (c, s))
    out.metadata.update(mesh.metadata)
    out.metadata["ple_cut_by"] = [*mesh.metadata.get("ple_cut_by", ()), *bodies]
    return out
