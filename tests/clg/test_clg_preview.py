"""What the add-on's CLG rig asks of the core: voxel boundary surfaces, a CLG on an edited pattern,
one chunk union shown, and meshes of a region's chunk copies."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from clg_reference import inside
from ple.clg.grid import voxel_surface
from ple.clg.ir import clg_from_dict, clg_to_dict
from ple.clg.query import compiled
from ple.errors import PleError
from ple.meshing.clg import mesh_clg
from ple.program.clg_sources import load_clg
from test_clg_pmc import random_clg


@pytest.mark.parametrize("seed", range(3))
def test_voxel_surface_encloses_the_filled_voxels(seed):
    rng = np.random.default_rng(seed)
    vox = rng.random((6, 5, 4)) < 0.45
    lo, hi = np.array([-1.0, 0.5, 2.0]), np.array([2.0, 3.0, 2.8])
    v, q = voxel_surface(vox, lo, hi)
    tri = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    mesh = trimesh.Trimesh(v, tri, process=False)
    cell = np.prod((hi - lo) / np.array(vox.shape))
    assert mesh.volume == pytest.approx(vox.sum() * cell, rel=1e-12)
    assert np.all(v >= lo - 1e-12) and np.all(v <= hi + 1e-12)
    # one quad per face between a filled and an empty voxel (outside counts as empty)
    pad = np.pad(vox, 1)
    faces = sum(int(np.count_nonzero(np.diff(pad.astype(int), axis=a))) for a in range(3))
    assert len(q) == faces


def test_with_pattern_and_showing():
    rng = np.random.default_rng(4)
    data = random_clg(rng, "steady")
    clg = clg_from_dict(data)
    moved = json.loads(json.dumps(data))
    moved["pattern"]["U"]["similarity"]["vector"][0] = 1.3
    want = clg_from_dict(moved)
    got = clg.with_pattern(want.pattern)
    p = compiled(want).lo - 0.2 + rng.random((2000, 3)) * (compiled(want).hi - compiled(want).lo + 0.4)
    assert np.array_equal(compiled(got).pmc(p), inside(moved, want, p))
    name = sorted(data["chunks"])[0]
    one = dict(moved, solid={"union": [name]})
    assert np.array_equal(compiled(got.showing(name)).pmc(p), inside(one, clg_from_dict(one), p))
    with pytest.raises(PleError, match="unknown chunk 'nope'"):
        clg.showing("nope")


def test_region_mesh_is_the_smaller_pattern():
    """On a steady pattern, the mesh of region 0:2 along U is the mesh of the CLG with U count 2."""
    clg = load_clg("shelled")
    data = json.loads(json.dumps(clg_to_dict(clg)))
    data["pattern"]["U"]["count"] = 2
    small = clg_from_dict(data)
    lat = clg.pattern
    region = lat.region(f"0:2,0:{lat.counts[1]},0:{lat.counts[2]}")
    a, b = mesh_clg(clg, 16, region), mesh_clg(small, 16)
    assert a.is_watertight and a.volume == pytest.approx(b.volume, rel=1e-9)
    assert mesh_clg(clg, 16).volume > 1.2 * a.volume
