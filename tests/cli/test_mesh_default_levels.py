"""``ple mesh`` without --levels: refined at the default levels when its STL fits, else at the
finest level that does (a note on stderr); an explicit --levels is kept."""

from __future__ import annotations

import ple.cli.mesh as mesh_cli
from ple.cli.main import main
from ple.io.export import read_back
from ple.meshing.tessellate import tessellate
from ple.model.budget import mesh_triangles, streamed_stl_bytes
from ple.program.sources import load_lattice


def test_the_finest_level_that_fits_is_chosen_and_said(tmp_path, capsys, monkeypatch):
    lat = load_lattice("cubic", {"n": 2})
    region = lat.region()
    # a cap between the estimates of 2 and 3 levels: 2 levels fit, 3 and 4 do not
    two, three = (streamed_stl_bytes(mesh_triangles(lat, region, "refined", k, 16)) for k in (2, 3))
    assert two < three
    monkeypatch.setattr(mesh_cli, "DEFAULT_MESH_BYTES", (two + three) // 2)
    out = tmp_path / "m.stl"
    assert main(["mesh", "cubic", "--param", "n=2", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "refined at 4 levels (the default)" in err and "meshing at 2 levels" in err
    want = tessellate(lat, None, "refined", 2)  # independent: the in-memory mesh at 2 levels
    got = read_back(out)
    assert len(got.faces) == len(want.faces) and got.is_watertight
    # an explicit --levels is the user's: kept, and nothing is said
    assert main(["mesh", "cubic", "--param", "n=2", "--levels", "3", "--out", str(tmp_path / "k.stl")]) == 0
    assert "note:" not in capsys.readouterr().err
    assert len(read_back(tmp_path / "k.stl").faces) == len(tessellate(lat, None, "refined", 3).faces)
    # no level within the cap: 0 levels (the smallest refined mesh), said
    monkeypatch.setattr(mesh_cli, "DEFAULT_MESH_BYTES", 10)
    assert main(["mesh", "cubic", "--param", "n=2", "--out", str(tmp_path / "z.stl")]) == 0
    assert "meshing at 0 levels" in capsys.readouterr().err
    assert len(read_back(tmp_path / "z.stl").faces) == len(tessellate(lat, None, "refined", 0).faces)
    # nothing fits the memory: the default's own refusal (exit 2, one line, no file)
    assert main(["mesh", "cubic", "--param", "n=2", "--max-memory", "1K", "--out", str(tmp_path / "n.stl")]) == 2
    err = capsys.readouterr().err
    assert "note:" not in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "n.stl").exists()
