"""A streamed STL whose cleanliness check finds unclean hubs falls back to exact unions made in
memory: that fallback is estimated before it starts and refused (exit 2, one line, no file, the
user's file untouched) when it exceeds --max-memory."""

from __future__ import annotations

from ple.cli.main import main
from ple.meshing.tessellate import _Tessellator
from ple.program.sources import load_lattice


def test_unions_in_memory_are_estimated_before_they_start(tmp_path, capsys):
    lat = load_lattice("warped", {"n": 12})
    report, _ = _Tessellator(lat, lat.region(), "cnt", 0, 16).find_unclean()
    assert len(report.nodes) > 0  # independent: the detector itself finds unclean hubs here
    out = tmp_path / "w.stl"
    out.write_bytes(b"users file")
    code = main(["mesh", "warped", "--param", "n=12", "--style", "cnt", "--max-memory", "10M", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{len(report.nodes):,} unclean hubs need exact unions" in err and "--max-memory" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == b"users file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.stl"]
    # within the limit the same command writes the united mesh
    assert main(["mesh", "warped", "--param", "n=12", "--style", "cnt", "--out", str(out)]) == 0
    assert out.read_bytes()[:3] == b"PLE"
