"""Lattices filling a body by ``any`` are cut at the body's surface when meshed: the mesh is
watertight, lies inside the body, and its volume is within 1 % of Monte Carlo over
(lattice ∩ body): the body's inside by its face planes (a convex part) or by its
two boxes (a turned L), the lattice by point membership of its exact balls and beams."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.body import BodyFilter
from ple.filters.cleanup import NodeSet
from ple.io.bodyfile import body_from_trimesh
from ple.meshing.tessellate import iter_triangles, tessellate, tessellation_box, weld_chunks
from ple.program.sources import load_lattice
from ple.queries import biq

pytest.importorskip("manifold3d")


def convex_part():
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.apply_transform(np.diag([2.3, 1.8, 1.5, 1.0]) @ trimesh.transformations.random_rotation_matrix(
        np.random.default_rng(5).random(3)))
    mesh.apply_translation([4.4, 4.6, 4.5])
    return mesh


L_BOXES = (([1.2, 1.3, 1.1], [8.2, 3.9, 7.6]), ([1.2, 1.3, 1.1], [3.7, 8.4, 7.6]))
L_TURN = trimesh.transformations.rotation_matrix(0.3, [1, 2, 3], [4.5, 4.5, 4.5])


def l_part():
    """A non-convex L: the union of two boxes (manifold3d), turned."""
    from manifold3d import Manifold

    solid = None
    for lo, hi in L_BOXES:
        box = Manifold.cube(np.subtract(hi, lo).tolist()).translate(lo)
        solid = box if solid is None else solid + box
    m = solid.to_mesh()
    mesh = trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts))
    mesh.apply_transform(L_TURN)
    return mesh


def inside_l(mesh, p):
    q = (np.linalg.inv(L_TURN) @ np.c_[p, np.ones(len(p))].T).T[:, :3]
    return np.any([np.all((q > lo) & (q < hi), axis=1) for lo, hi in L_BOXES], axis=0)


def inside_by_planes(mesh, p):
    """Below every face plane (a convex mesh). A sixteenth of the planes first: most points
    outside are above one of them, and only the rest are tested against all."""
    n = mesh.face_normals
    off = np.einsum("ij,ij->i", n, mesh.triangles[:, 0])
    out = np.empty(len(p), bool)
    for s in range(0, len(p), 4096):
        q = p[s:s + 4096]
        rows = np.flatnonzero((q @ n[::16].T < off[None, ::16]).all(axis=1))
        out[s:s + 4096] = False
        out[s + rows] = (q[rows] @ n.T < off[None]).all(axis=1)
    return out


def monte_carlo(mesh, lat, inside, n=800_000, seed=1):
    """Volume of lattice ∩ body: uniform points in the body's box, inside the body (``inside``)
    and inside a kept ball or beam (``biq.pmc`` of the filtered lattice)."""
    rng = np.random.default_rng(seed)
    lo, hi = mesh.bounds
    p = rng.uniform(lo, hi, (n, 3))
    hit = inside(mesh, p)
    rows = np.flatnonzero(hit)
    hit[rows] = biq.pmc(lat, p[rows])
    frac = hit.mean()
    box = float(np.prod(hi - lo))
    return frac * box, np.sqrt(frac * (1 - frac) / n) * box


@pytest.mark.parametrize("make, inside", [(convex_part, inside_by_planes),
                                          (l_part, inside_l)])
def test_any_mesh_is_cut_at_the_surface(make, inside):
    part = make()
    body = body_from_trimesh(part)
    lat = load_lattice("cubic", {"radius": 0.25}).with_filter(BodyFilter(body, "any"))
    mesh = tessellate(lat)
    assert mesh.is_watertight and mesh.is_volume
    mc, se = monte_carlo(part, lat, inside)
    assert 3 * se < 0.01 * mc  # the estimate is sharp enough for the 1 % claim
    assert mesh.volume == pytest.approx(mc, rel=0.01)
    # the uncut mesh of the same kept set sticks out of the body: the cut removed real volume
    base = load_lattice("cubic", {"radius": 0.25})
    uncut = tessellate(base.with_filter(NodeSet(base, lat.evaluate().node_index)))
    assert uncut.volume > 1.02 * mesh.volume
    v = np.asarray(mesh.vertices)
    out = np.flatnonzero(~body.contains(v))
    assert body.distance(v[out], 1e-3).max(initial=0) < 1e-5  # every vertex on or inside the surface


def test_every_mesh_door_cuts(tmp_path):
    part = convex_part()
    body = body_from_trimesh(part)
    lat = load_lattice("cubic").with_filter(BodyFilter(body, "any"))
    mesh = tessellate(lat, style="cnt")
    chunks = list(iter_triangles(lat, style="cnt"))  # the add-on's door: one chunk, already cut
    v, f = weld_chunks(chunks)
    assert len(f) == len(mesh.faces) and np.isclose(trimesh.Trimesh(v, f).volume, mesh.volume)
    unfiltered_kept = load_lattice("cubic").with_filter(BodyFilter(body, "any")).evaluate()
    balls = unfiltered_kept.center
    assert (~body.contains(balls)).any()  # some kept balls have their centres outside: cut
    with pytest.raises(PleError, match="without parts"):
        tessellation_box(lat, None, "0:2,0:2,0:2", "cnt")
    path = tmp_path / "part.stl"
    part.export(path)
    out = tmp_path / "cut.stl"
    assert main(["mesh", "cubic", "--body", str(path), "--fill", "any", "--style", "cnt", "--out", str(out)]) == 0
    got = trimesh.load(out, force="mesh")
    assert got.is_watertight and got.volume == pytest.approx(mesh.volume, rel=1e-4)
    inside = load_lattice("cubic").with_filter(BodyFilter(body, "inside"))
    whole = tessellate(inside, style="cnt")  # inside: nothing to cut, the mesh is the fast path's
    assert whole.volume < mesh.volume
