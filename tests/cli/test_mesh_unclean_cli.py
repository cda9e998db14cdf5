"""``ple mesh`` finds an unclean lattice's hubs once: the mesher's report gives both the union
line and the warning (the design-rule check runs only where the mesher did not look)."""

from __future__ import annotations

import pytest
from ple.cli import mesh as mesh_cli
from ple.cli.main import main
from ple.io.irfile import save_ir
from ple.measure.check import is_clean
from ple.meshing import tessellate as tess_mod

from tests.meshing.test_unclean import random_unclean_lattice

pytest.importorskip("manifold3d")


@pytest.fixture
def unclean(tmp_path):
    lat = random_unclean_lattice(1)
    assert is_clean(lat) is False  # the design rule agrees: beams overlap
    save_ir(lat, tmp_path / "u.json")
    return str(tmp_path / "u.json")


@pytest.mark.parametrize("out", ["x.stl", "x.ply"])
def test_mesh_runs_the_unclean_detector_once(out, unclean, tmp_path, monkeypatch, capsys):
    calls = []
    real = tess_mod.find_unclean
    monkeypatch.setattr(tess_mod, "find_unclean", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(mesh_cli, "is_clean", lambda *a, **k: pytest.fail("the detector ran twice"))
    assert main(["mesh", unclean, "--style", "cnt", "--out", str(tmp_path / out)]) == 0
    cap = capsys.readouterr()
    assert len(calls) == 1
    assert "united with manifold3d" in cap.out and "the lattice is not clean" in cap.err


def test_unchecked_styles_still_warn(unclean, tmp_path, capsys):
    assert main(["mesh", unclean, "--style", "balls-beams", "--out", str(tmp_path / "x.stl")]) == 0
    assert "the lattice is not clean" in capsys.readouterr().err
