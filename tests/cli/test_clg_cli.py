"""``ple clg pmc|ray|render|mesh`` end to end on the CLG presets (by name) and bad inputs (exit 2)."""

from __future__ import annotations

import numpy as np
import pytest
from ple.clg.query import compiled
from ple.cli.main import main
from ple.program.clg_sources import load_clg


def test_pmc_and_ray(tmp_path):
    comp = compiled(load_clg("shelled"))
    pts = np.random.default_rng(0).uniform(-0.5, 4, (500, 3))
    np.save(tmp_path / "p.npy", pts)
    assert main(["clg", "pmc", "shelled", "--points", str(tmp_path / "p.npy"), "--out", str(tmp_path / "i.npy")]) == 0
    assert np.array_equal(np.load(tmp_path / "i.npy"), comp.pmc(pts))
    rays = np.zeros((3, 6))
    rays[:, :3] = [[0, 0, 9], [0.5, 0.5, 9], [10, 10, 10]]
    rays[:, 5] = -1
    np.save(tmp_path / "r.npy", rays)
    assert main(["clg", "ray", "shelled", "--rays", str(tmp_path / "r.npy"), "--out", str(tmp_path / "t.npy")]) == 0
    t = np.load(tmp_path / "t.npy")
    # straight down the column x = y = 0: the +z beam of the top copy (group (0, 0, 3)) reaches node
    # (0, 0, 4), beyond the count range, with radius 0.2: first hit at z = 4.2
    assert t[0] == pytest.approx(9 - 4.2, rel=1e-9)
    assert np.isinf(t[1]) and np.isinf(t[2])


def test_render_and_mesh(tmp_path):
    from PIL import Image
    assert main(["clg", "render", "shelled", "--param", "x=1", "--out", str(tmp_path / "a.png")]) == 2
    assert main(["clg", "render", "shelled", "--size", "48,36", "--out", str(tmp_path / "a.png")]) == 0
    img = np.array(Image.open(tmp_path / "a.png"))
    assert img.shape == (36, 48) and (img < 200).mean() > 0.05
    assert main(["clg", "mesh", "connectors", "--param", "nu=2", "--param", "nv=2", "--segments", "16",
                 "--out", str(tmp_path / "c.stl")]) == 0
    import trimesh
    mesh = trimesh.load(tmp_path / "c.stl")
    assert mesh.is_watertight


@pytest.mark.parametrize("argv", [["clg", "pmc", "shelled", "--points", "missing.npy", "--out", "x.npy"],
                                  ["clg", "voxelize", "shelled", "--grid", "2,2", "--out", "v.npy"],
                                  ["clg", "voxelize", "shelled", "--grid", "2,2,2", "--bounds", "0,0,0,1,1",
                                   "--out", "v.npy"],
                                  ["clg", "info", "no_such_clg"],
                                  ["slice", "cubic", "--layer", "0", "--pixel", "0.1", "--out", "d"]])
def test_bad_inputs_exit_2(argv, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
