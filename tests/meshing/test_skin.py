"""Skins: watertight, and their volume within 1 % of Monte Carlo over the true solid (inside the
body and either within the thickness of its surface, by brute-force distances, or inside the
trimmed lattice, by point membership of its exact balls and beams)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from ple.filters.body import BodyFilter
from ple.io.bodyfile import body_from_trimesh
from ple.meshing.skin import skin
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice
from ple.queries import biq

pytest.importorskip("manifold3d")


def convex_inside_depth(mesh, points):
    """For a convex polyhedron: (inside, depth) by its face planes alone: a point is inside when it
    is below every plane, and its distance to the surface is then the smallest plane distance (for
    a point outside, ``depth`` is only some plane's negative distance)."""
    n = mesh.face_normals
    off = np.einsum("ij,ij->i", n, mesh.triangles[:, 0])
    depth = np.full(len(points), np.inf)
    for s in range(0, len(points), 4096):
        q = points[s:s + 4096]
        depth[s:s + 4096] = (off[None, ::16] - q @ n[::16].T).min(axis=1)  # a sixteenth of the planes first
        rows = np.flatnonzero(depth[s:s + 4096] > 0)  # below all of those: measured against every plane
        depth[s + rows] = (off[None] - q[rows] @ n.T).min(axis=1)
    return depth > 0, depth


@pytest.fixture(scope="module")
def part():
    mesh = trimesh.creation.icosphere(subdivisions=3)  # convex: its planes give the independent truth
    mesh.apply_transform(np.diag([2.3, 1.8, 1.5, 1.0]) @ trimesh.transformations.random_rotation_matrix(
        np.random.default_rng(2).random(3)))
    mesh.apply_translation([4.5, 4.5, 4.5])
    assert mesh.is_convex
    return mesh


@pytest.fixture(scope="module")
def samples(part):
    """Uniform points (600,000) in the part's box, kept where they are inside it, with their
    depth below its surface: the sample of every Monte Carlo estimate here."""
    lo, hi = part.bounds
    p = np.random.default_rng(0).uniform(lo, hi, (600_000, 3))
    inside, depth = convex_inside_depth(part, p)
    return p[inside], depth[inside]


def monte_carlo(mesh, samples, thickness, lat=None):
    """Volume of the true solid: the body's exact volume times the fraction of the ``samples``
    inside it that lie within ``thickness`` of its surface or inside the lattice's balls and beams."""
    p, depth = samples
    solid = depth < thickness
    if lat is not None:
        rest = np.flatnonzero(~solid)
        solid[rest] = biq.pmc(lat, p[rest])
    frac = solid.mean()
    return frac * mesh.volume, np.sqrt(frac * (1 - frac) / len(p)) * mesh.volume


@pytest.mark.parametrize("mode", ["any"])
def test_skinned_lattice_is_watertight_with_the_monte_carlo_volume(part, samples, mode):
    body = body_from_trimesh(part)
    lat = load_lattice("cubic").with_filter(BodyFilter(body, mode))
    out = skin(body, 0.3, tessellate(lat))
    assert out.is_watertight and out.is_volume
    mc, se = monte_carlo(part, samples, 0.3, lat)
    assert 3 * se < 0.01 * mc  # the estimate is sharp enough for the 1 % claim
    assert out.volume == pytest.approx(mc, rel=0.01)
    # the lattice adds volume to the bare shell (the union is not the shell alone)
    shell = skin(body, 0.3)
    assert shell.is_watertight
    mc_shell, _ = monte_carlo(part, samples, 0.3)
    assert shell.volume == pytest.approx(mc_shell, rel=0.01)
    assert out.volume > shell.volume * 1.02


@pytest.fixture(scope="module")
def skinned(part, tmp_path_factory):
    """The part as an STL, and ``ple skin cubic --body part.stl --thickness 0.4`` of it (the file
    both doors below are compared with)."""
    from ple.cli.main import main

    folder = tmp_path_factory.mktemp("skin")
    path, out = folder / "part.stl", folder / "skinned.stl"
    part.export(path)
    assert main(["skin", "cubic", "--body", str(path), "--thickness", "0.4", "--out", str(out)]) == 0
    return path, out


def test_skin_command(tmp_path, part, skinned, capsys):
    from ple.cli.main import main

    _, out = skinned
    got = trimesh.load(out, force="mesh", process=False)
    body = body_from_trimesh(part)
    want = skin(body, 0.4, tessellate(load_lattice("cubic").with_filter(BodyFilter(body, "any")), cut=False))
    # the file as read back (float32; slivers of a few float32 steps collapsed before writing) is closed
    merged = trimesh.Trimesh(got.vertices, got.faces)  # vertices merged by position, as a slicer reads STL
    assert want.is_watertight and merged.is_watertight
    assert abs(len(got.faces) - len(want.faces)) <= 0.01 * len(want.faces)
    assert got.volume == pytest.approx(want.volume, rel=1e-4)
    assert main(["skin", "cubic", "--thickness", "0.4", "--out", str(tmp_path / "x.stl")]) == 2
    assert "needs --body" in capsys.readouterr().err


def test_mesh_skin_flag_writes_the_skinned_solid(tmp_path, skinned, capsys):
    from ple.cli.main import main

    path, a = skinned
    b = tmp_path / "b.stl"
    assert main(["mesh", "cubic", "--body", str(path), "--fill", "any", "--skin", "0.4", "--out", str(b)]) == 0
    got, want = (trimesh.load(x, force="mesh", process=False) for x in (b, a))  # the same solid as ple skin
    assert len(got.faces) == len(want.faces) and got.volume == pytest.approx(want.volume, rel=1e-6)
    assert main(["mesh", "cubic", "--skin", "0.4", "--out", str(b)]) == 2
    assert "--skin needs a body" in capsys.readouterr().err
    assert main(["mesh", "cubic", "--body", str(path), "--skin", "0.4", "--check", "--out", str(b)]) == 2
