"""app.pipeline.estimate (the one estimate of a mesh: the triangles a style makes, before
tessellating) and meshing.tessellate.weld_chunks (the boxes of iter_triangles welded into one mesh)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from ple.app.pipeline import MeshRequest, plan
from ple.app.pipeline import estimate as pipeline_estimate
from ple.errors import PleError
from ple.meshing.styles import STYLES
from ple.meshing.tessellate import iter_triangles, tessellate, weld_chunks
from ple.model.budget import estimate
from ple.program.sources import load_lattice


@pytest.mark.parametrize("preset", ["cubic", "octet", "fig6_3"])
@pytest.mark.parametrize("style", ["chocc", "cnt"])
def test_triangle_estimate_within_a_factor_two(preset, style):
    lat = load_lattice(preset)
    got = len(tessellate(lat, "0:4,0:3,0:2", style).faces)
    est = mesh_estimate(lat, "0:4,0:3,0:2", style).triangles
    assert 0.5 * got <= est <= 2.0 * got, (got, est)


def mesh_estimate(lat, region, style, levels=None):
    """The add-on's form of the one estimate (balls, beams, triangles, memory in Blender)."""
    return pipeline_estimate(plan(MeshRequest(lat, region, style, levels)), "memory").work


def test_every_style_is_estimated():
    lat = load_lattice("cubic")
    plain = estimate(lat, "0:2,0:2,0:2")
    for name in STYLES:
        est = mesh_estimate(lat, "0:2,0:2,0:2", name)
        assert est.triangles > 0 and est.bytes > plain.bytes and est.balls == plain.balls
    assert mesh_estimate(lat, "0:2,0:2,0:2", "refined", levels=2).triangles < \
        mesh_estimate(lat, "0:2,0:2,0:2", "refined", levels=4).triangles
    with pytest.raises(PleError, match="style 'nope': expected one of"):
        mesh_estimate(lat, None, "nope")


@pytest.mark.parametrize("preset,style", [("cubic", "chocc"), ("fig6_3", "cnt"), ("octet", "chocc")])
def test_weld_chunks_is_the_whole_tessellation(preset, style):
    lat = load_lattice(preset)
    region = "0:3,0:3,0:2"
    want = tessellate(lat, region, style)
    verts, faces = weld_chunks(iter_triangles(lat, region, style, max_groups=3))
    got = trimesh.Trimesh(verts, faces, process=False)
    assert len(got.vertices) == len(want.vertices) and len(got.faces) == len(want.faces)
    assert got.is_watertight and np.isclose(got.volume, want.volume, rtol=1e-9)
    assert np.allclose(np.sort(np.asarray(got.vertices), axis=0), np.sort(np.asarray(want.vertices), axis=0))


def test_weld_chunks_of_nothing():
    verts, faces = weld_chunks([])
    assert verts.shape == (0, 3) and faces.shape == (0, 3)
