"""``ple bench curved`` (also the lattice rows of ``ple bench mesh``): every path of a row meshes
the same lattice, so the per-hub, batched (1 and 2 workers) and writer-only rows must write the
same number of triangles, equal to the streamed STL written independently here; each row's peak
memory is its own child's."""

from __future__ import annotations

import json

import numpy as np
from ple.bench import curved
from ple.bench.curved import bench_lattice
from ple.cli.main import main
from ple.io.export import write_stl
from ple.meshing.tessellate import iter_triangles, output_grid


def test_curved_bench_rows_agree(tmp_path, capsys):
    out = tmp_path / "b.json"
    # a row is seven child processes: the refined rows of curved and regular, and warped's cnt row,
    # cover both styles' paths
    assert main(["bench", "curved", "--n", "4", "--warped-n", "3", "--styles", "refined", "--levels", "1",
                 "--repeat", "1", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [(r["lattice"], r["style"]) for r in data["rows"]] == [
        ("curved", "refined"), ("regular", "refined"), ("warped", "cnt")]
    for row in data["rows"]:
        lat = bench_lattice(row["lattice"], row["n"])
        expect = write_stl(tmp_path / "x.stl", iter_triangles(lat, None, row["style"], row["levels"], workers=1),
                           grid=output_grid(lat))
        counts = {r["triangles"] for r in row["runs"]} | {row["stl_writer_only"]["triangles"]}
        assert counts == {expect}, row
        assert [r["path"] for r in row["runs"]][:1] == (["per-hub"] if row["lattice"] == "curved" else ["batched"])
        assert all(0.01 < r["peak_rss_gb"] < 8 for r in row["runs"])
        assert row["cleanliness_check"]["unclean_hubs"] >= 0
        assert np.isfinite(row["best_triangles_per_s"]) and row["best_triangles_per_s"] > 0


def test_a_repeated_row_keeps_its_fastest_run(monkeypatch):
    """``--repeat``: each batched row is run that many times (in a child each) and the fastest kept,
    with every run's seconds."""
    seconds = iter([3.0, 1.0, 2.0])
    monkeypatch.setattr(curved, "_child", lambda *spec: {"spec": spec, "seconds": next(seconds)})
    best = curved._fastest(("curved", 4, "cnt", 0, "batched", 1), 3)
    assert best["seconds"] == 1.0 and best["seconds_all"] == [3.0, 1.0, 2.0]
    assert best["spec"] == ("curved", 4, "cnt", 0, "batched", 1)
