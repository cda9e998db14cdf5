"""make demo's pipeline: program → LiL filter → refined mesh → STL and 3MF beam lattice."""

from __future__ import annotations

import zipfile

import trimesh
from lxml import etree
from ple.program.sources import load_lattice

from tools.demo import main


def test_demo_pipeline_outputs(tmp_path, capsys):
    params = ["--out", str(tmp_path), "--levels", "1", "--no-render"]
    assert main(params) == 0
    text = capsys.readouterr().out
    assert "watertight=True" in text
    mesh = trimesh.load(tmp_path / "hier_lil2.stl")
    assert mesh.is_watertight and mesh.volume > 0
    from tools.demo import DEFAULT_PARAMS
    kept = load_lattice("hier_lil2", DEFAULT_PARAMS).evaluate()
    with zipfile.ZipFile(tmp_path / "hier_lil2_beams.3mf") as z:
        model = etree.fromstring(z.read("3D/3dmodel.model"))
    n_vertices = len(model.findall(".//{*}vertex"))
    n_beams = len(model.findall(".//{*}beam"))
    assert (n_vertices, n_beams) == (len(kept.center), len(kept.beam_nodes))
