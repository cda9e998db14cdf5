"""A streamed STL whose cleanliness check finds unclean hubs streams local unions of them, one at
a time: the largest is estimated before the stream starts and refused (exit 2, one line, no file,
the user's file untouched) when it exceeds --max-memory."""

from __future__ import annotations

from ple.cli.main import main
from ple.meshing.tessellate import Tessellator
from ple.program.sources import load_lattice
from ple.queries.overlaps import unclean_pairs

# thick diagonal beams across a slab: they cross the balls and beams of their neighbours
CROSSING = """
def lattice(n: Range(2, 40) = 6):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.22)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.add_beam(a, a, 1, -1, 0)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(2, Translation(Vec(0, 0, 1)))
    return lat
"""


def test_local_unions_are_estimated_before_they_start(tmp_path, capsys):
    src = tmp_path / "crossing.py"
    src.write_text(CROSSING)
    lat = load_lattice(str(src), {"n": 6})
    assert unclean_pairs(lat)["unclean_pairs"] > 0  # independent: the beams do cross
    report, _ = Tessellator(lat, lat.region(), "cnt", 0, 16).find_unclean()
    assert len(report.nodes) > 0
    out = tmp_path / "w.stl"
    out.write_bytes(b"users file")
    code = main(["mesh", str(src), "--param", "n=6", "--style", "cnt", "--max-memory", "1M", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert "local unions of unclean hubs" in err and "--max-memory" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == b"users file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["crossing.py", "w.stl"]
    # within the limit the same command writes the united mesh
    assert main(["mesh", str(src), "--param", "n=6", "--style", "cnt", "--out", str(out)]) == 0
    assert out.read_bytes()[:3] == b"PLE"
