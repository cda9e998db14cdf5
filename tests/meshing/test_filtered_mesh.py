"""Meshes of filtered lattices (a program's Stencil / LiL / implicit filter, thesis §9):
only surviving nodes get hubs, beams exist where both ends survive, and the mesh is closed."""

from __future__ import annotations

import json

import numpy as np
import pytest
from ple.cli.main import main
from ple.cli.mesh import monte_carlo_volume
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

CASES = [("hier_stencil", {"n": 7, "period": 3}), ("hier_lil2", {"n": 8, "coarse_cells": 1}),
         ("hier_gyroid", {"n": 7, "cell": 5.0, "level": 0.0})]


@pytest.mark.parametrize("name, params", CASES)
@pytest.mark.parametrize("style", ["cnt", "chocc"])
def test_filtered_mesh_is_closed(name, params, style):
    lat = load_lattice(name, params)
    kept = lat.evaluate()
    assert 0 < len(kept.center) < lat.node_count()  # the filter really removes nodes
    mesh = tessellate(lat, style=style)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert 0 < mesh.volume < tessellate(_without_filter(lat), style=style).volume
    # the mesh spans the kept balls (hubs bulge to the inflated radius r⁺, about 2.6 r at valence 18)
    lo = (kept.center - kept.radius[:, None]).min(0)
    hi = (kept.center + kept.radius[:, None]).max(0)
    assert np.allclose(mesh.bounds, [lo, hi], atol=2.0 * kept.radius.max())


@pytest.mark.parametrize("name, params", CASES)
def test_refined_filtered_mesh_has_the_filtered_volume(name, params):
    """Independent truth: Monte Carlo volume of the union of the kept balls and cone-beams."""
    lat = load_lattice(name, params)
    mesh = tessellate(lat, style="refined", levels=3)
    assert mesh.is_watertight and mesh.is_winding_consistent
    est, err = monte_carlo_volume(lat, lat.region(), samples=400_000)
    assert abs(mesh.volume - est) < max(4 * err, 0.04 * est)


def _without_filter(lat):
    other = lat.copy()
    other.set_filter(None)
    return other


def test_mesh_check_of_a_filtered_lattice(tmp_path, capsys):
    out = tmp_path / "m.stl"
    assert main(["mesh", "hier_stencil", "--param", "n=7", "--param", "period=3", "--style", "refined",
                 "--levels", "3",
                 "--out", str(out), "--check"]) == 0
    text = capsys.readouterr().out
    rep = json.loads(text[text.index("{"):])
    assert rep["watertight"] and rep["lattice_volume_source"].startswith("ple info (sum over kept hubs)")
    assert abs(rep["relative_volume_error"]) < 0.04
