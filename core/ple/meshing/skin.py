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
from typing import TYPE_CHECKING

import numpy as np

from ..errors import PleError, echo
from ..filters.body import Body, body_filters
from .selfcheck import self_intersections
from .weld import COLLAPSE_GRIDS, grid_spacing

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh

MAX_SDF_SAMPLES = 8_000_000  # grid samples of the signed distance


def _manifold(vertices, faces):
    """A manifold3d solid of a closed mesh, its vertices in 64 bits (``Mesh64``): manifold3d
    computes in doubles, so a body of size 1e30 filled by a lattice of size 1e30 keeps its cells."""
    from manifold3d import Manifold, Mesh64  # optional: only skins and cuts need manifold3d

    m = Manifold(Mesh64(vert_properties=np.array(vertices, dtype=np.float64, order="C"),  # copies: writeable
                        tri_verts=np.array(faces, dtype=np.uint64, order="C")))
    if m.status().name != "NoError":
        raise PleError(f"the mesh is not a closed manifold for Booleans ({m.status().name})")
    return m


def _solid(body: Body):
    """The body as a manifold3d solid; refused if it intersects itself: a Boolean would count
    the overlap twice and leave a mesh that does not close (``ple.meshing.selfcheck``)."""
    pairs = self_intersections(body.vertices, body.faces)
    if len(pairs):
        at = body.triangles[pairs[0, 0]].mean(axis=0)
        raise PleError(f"{body.name}: the body intersects itself ({len(pairs):,} pairs of faces cross, e.g. near "
                       f"({at[0]:.4g}, {at[1]:.4g}, {at[2]:.4g})); cutting or skinning needs a body that does "
                       "not: repair it, e.g. unite its parts")
    return _manifold(body.vertices, body.faces)


def _trimesh(m) -> trimesh.Trimesh:
    """The Boolean's result with its slivers (features under a few float32 steps at its size,
    which a float32 file cannot keep apart) removed by manifold3d itself: it stays manifold."""
    import trimesh
    if not m.is_empty():
        box = np.asarray(m.bounding_box(), float)
        m = m.simplify(COLLAPSE_GRIDS * grid_spacing(box[:3], box[3:]))
    mesh = m.to_mesh64()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties, float)[:, :3], np.asarray(mesh.tri_verts, np.int64),
                           process=False)


def inward_offset(body: Body, thickness: float, edge: float | None = None):
    """The manifold {x : sd(x) ≥ thickness} (empty when the body is thinner than 2·thickness)."""
    from manifold3d import Manifold

    if not thickness > 0:
        raise PleError(f"skin thickness must be positive, got {echo(thickness)}")
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
    # sliding-midpoint splits and unshrunk boxes: the same distances, twice as fast for samples on a surface
    tree = cKDTree(_surface_samples(body, spacing), balanced_tree=False, compact_nodes=False)
    ds, _ = tree.query(pts, distance_upper_bound=high + spacing)
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
    outer = _solid(body)
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


def clip_to_bodies(mesh: trimesh.Trimesh, bodies, contain=None) -> trimesh.Trimesh:
    """``mesh`` (closed) intersected with every body (closed): what sticks out is cut at their
    surfaces. One watertight solid; an empty mesh stays empty. A body whose surface stays away
    from the mesh's box (``surface_meets_box``) holds all of the mesh or none of it: no Boolean,
    whose tolerance (1e-12 of the largest coordinate) a body of size 1e30 around a lattice of
    size 10 would make coarser than the lattice. ``contain`` runs the Booleans, given as a
    function that returns the cut mesh, and returns that mesh (in a child process that a signal
    stops: ``ple.program.meshes.mesh_contained``); None runs them here."""
    import trimesh
    if not bodies or not len(mesh.faces):
        return mesh
    for body in bodies:
        if not body.closed:
            raise PleError(f"{body.name}: an open body (winding-number fallback) cannot cut a mesh: close it")
    lo, hi = mesh.bounds
    crossing = [b for b in bodies if surface_meets_box(b, lo, hi)]
    if any(not b.contains(mesh.vertices[:1])[0] for b in bodies if b not in crossing):  # the mesh lies outside
        out = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), process=False)
    elif crossing:
        out = (contain or (lambda make: make()))(lambda: _cut(mesh, crossing))
    else:  # inside every body
        out = mesh.copy()
    out.metadata.update(mesh.metadata)
    out.metadata["ple_cut_by"] = [*mesh.metadata.get("ple_cut_by", ()), *bodies]
    return out


def surface_meets_box(body: Body, lo, hi) -> bool:
    """Whether a triangle of the body may meet the box [lo, hi] (their boxes overlap, the box
    grown by a float32 step at its size); if none does, the box lies wholly inside or outside."""
    pad = grid_spacing(lo, hi)
    tri = body.triangles
    near = (tri.min(axis=1) <= np.asarray(hi) + pad) & (tri.max(axis=1) >= np.asarray(lo) - pad)
    return bool(np.any(np.all(near, axis=1)))


def _cut(mesh: trimesh.Trimesh, bodies) -> trimesh.Trimesh:
    """The Booleans of ``clip_to_bodies``. Refused (PleError) when manifold3d's tolerance, set by
    the largest coordinate of mesh and bodies, is coarser than the float32 steps the mesh is
    written with: the body's triangles that cross the lattice are far larger than it."""
    solid = _manifold(mesh.vertices, mesh.faces)
    for body in bodies:
        solid = solid ^ _solid(body)
    lo, hi = mesh.bounds
    step = COLLAPSE_GRIDS * grid_spacing(lo, hi)
    if solid.get_tolerance() > step:
        big = max(bodies, key=lambda b: float(np.max(b.hi - b.lo)))
        raise PleError(f"{big.name}: a body {float(np.max(big.hi - big.lo)):.3g} across, whose surface crosses a "
                       f"lattice {float(np.max(hi - lo)):.3g} across, cannot cut it: the cut would be within "
                       f"{solid.get_tolerance():.3g}, coarser than the mesh's {step:.3g}; fill by 'inside' or "
                       "'centroid', or give the body finer triangles near the lattice")
    return _trimesh(solid)
