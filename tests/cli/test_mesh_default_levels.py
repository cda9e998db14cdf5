"""``ple mesh`` without --levels: refined at the default levels when the budgets take it, else
at the finest level that they take within the default STL size (a note on stderr); an explicit
--levels is kept."""

from __future__ import annotations

import shutil
from collections import namedtuple

import ple.cli.mesh as mesh_cli
from ple.cli.main import main
from ple.io.export import read_back
from ple.meshing.tessellate import tessellate
from ple.model.budget import mesh_triangles, streamed_stl_bytes
from ple.program.sources import load_lattice

Usage = namedtuple("Usage", "total used free")


def test_the_finest_level_that_fits_is_chosen_and_said(tmp_path, capsys, monkeypatch):
    lat = load_lattice("cubic", {"n": 2})
    region = lat.region()
    size = [streamed_stl_bytes(mesh_triangles(lat, region, "refined", k, 16)) for k in range(5)]
    assert size == sorted(size) and len(set(size)) == 5

    def mesh(name, *more):
        code = main(["mesh", "cubic", "--param", "n=2", *more, "--out", str(tmp_path / name)])
        return code, capsys.readouterr().err

    def faces(name):
        got = read_back(tmp_path / name)
        assert got.is_watertight
        return len(got.faces)

    # the default fits: 4 levels, whatever the cap (it is for lowered levels only), nothing said
    monkeypatch.setattr(mesh_cli, "DEFAULT_MESH_BYTES", 10)
    code, err = mesh("d.stl")
    assert code == 0 and "note:" not in err and faces("d.stl") == len(tessellate(lat, None, "refined", 4).faces)
    # the disk takes 3 levels, not 4: 3 levels, said with the reason
    real = shutil.disk_usage
    monkeypatch.setattr(shutil, "disk_usage", lambda p: Usage(*real(p)[:2], (size[3] + size[4]) // 2))
    monkeypatch.setattr(mesh_cli, "DEFAULT_MESH_BYTES", 1 << 40)
    code, err = mesh("m.stl")
    assert code == 0 and "refined at 4 levels (the default)" in err and "free in" in err
    assert "meshing at 3 levels" in err
    assert faces("m.stl") == len(tessellate(lat, None, "refined", 3).faces)  # independent: in memory
    # and the cap between 1 and 2 levels: 1 level
    monkeypatch.setattr(mesh_cli, "DEFAULT_MESH_BYTES", (size[1] + size[2]) // 2)
    code, err = mesh("o.stl")
    assert code == 0 and "meshing at 1 levels" in err
    assert faces("o.stl") == len(tessellate(lat, None, "refined", 1).faces)
    # no lowered level within the cap: 0 levels (the smallest refined mesh)
    monkeypatch.setattr(mesh_cli, "DEFAULT_MESH_BYTES", 10)
    code, err = mesh("z.stl")
    assert code == 0 and "meshing at 0 levels" in err
    assert faces("z.stl") == len(tessellate(lat, None, "refined", 0).faces)
    # an explicit --levels is the user's: kept (and refused by the disk as before)
    code, err = mesh("k.stl", "--levels", "2")
    assert code == 0 and "note:" not in err and faces("k.stl") == len(tessellate(lat, None, "refined", 2).faces)
    code, err = mesh("r.stl", "--levels", "4")
    assert code == 2 and "free in" in err and not (tmp_path / "r.stl").exists()
    # nothing fits the memory: the default's own refusal (exit 2, one line, no file)
    code, err = mesh("n.stl", "--max-memory", "1K")
    assert code == 2 and "note:" not in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "n.stl").exists()
