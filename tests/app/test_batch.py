"""ple batch: sweeps, manifest, resume, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from ple.app.batch import parse_sweep, plan, run_batch
from ple.cli.main import main
from ple.errors import PleError
from ple.program.runtime import Param
from ple.program.sources import load_lattice


def test_sweep_syntax():
    assert parse_sweep(Param("t", 0.1), "0.05:0.1:3") == pytest.approx([0.05, 0.075, 0.1])
    assert parse_sweep(Param("n", 2), "2:6:3") == [2, 4, 6]
    assert parse_sweep(Param("n", 2), "3,5") == [3, 5]
    with pytest.raises(PleError, match="lo:hi:n"):
        parse_sweep(Param("t", 0.1), "1:2")
    with pytest.raises(PleError, match="at least 1"):
        parse_sweep(Param("t", 0.1), "1:2:0")


def test_plan_is_the_cartesian_product():
    _, variants = plan("cubic", ["n=2:3:2", "radius=0.1,0.2,0.3"], "stl")
    assert len(variants) == 6
    assert len({v.filename for v in variants}) == 6
    assert {(v.params["n"], v.params["radius"]) for v in variants} == {(n, r) for n in (2, 3) for r in (0.1, 0.2, 0.3)}


def test_batch_writes_manifest_and_resumes(tmp_path):
    res = run_batch("cubic", ["n=2:3:2", "radius=0.1,0.2"], tmp_path, style="balls-beams", fmt="stl", jobs=2,
                    progress=False)
    assert res["written"] == 4 and res["skipped"] == 0
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert len(manifest["outputs"]) == 4
    for entry in manifest["outputs"]:
        mesh = trimesh.load(tmp_path / entry["file"])
        assert len(mesh.faces) == entry["triangles"]
        # the preview mesh spans the lattice's balls
        lat = load_lattice("cubic", entry["params"])
        lo, hi = lat.bounds()
        assert np.all(mesh.bounds[0] >= lo - 1e-6) and np.all(mesh.bounds[1] <= hi + 1e-6)
    # a re-run skips finished outputs; a deleted output is made again
    (tmp_path / manifest["outputs"][0]["file"]).unlink()
    res = run_batch("cubic", ["n=2:3:2", "radius=0.1,0.2"], tmp_path, style="balls-beams", progress=False)
    assert res["written"] == 1 and res["skipped"] == 3


def test_batch_cli_bad_input(tmp_path, capsys):
    assert main(["batch", "cubic", "--param", "nope=1", "--style", "balls-beams", "--out", str(tmp_path)]) == 2
    assert "unknown parameter" in capsys.readouterr().err
    # a variant the program rejects (count 0) is reported in the manifest and exits 2
    assert main(["batch", "cubic", "--param", "n=0,1", "--style", "balls-beams", "--out", str(tmp_path)]) == 2
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert [f["params"]["n"] for f in manifest["failures"]] == [0]
    assert [o["params"]["n"] for o in manifest["outputs"]] == [1]
