"""``ple mesh --check``: the written file checked as a consumer reads it (an STL in chunks, block
by block), and the mesh volume printed beside the volume ``ple info`` reports."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import trimesh
from ple.algebra.elements import beam_distance
from ple.cli.main import main
from ple.cli.mesh import file_triangles, monte_carlo_volume
from ple.io.export import export_mesh, read_back
from ple.io.spill import SpillFiles
from ple.meshing.selfcheck import check_triangles, self_intersections
from ple.program.sources import load_lattice


def test_volume_line_beside_ple_info(tmp_path, capsys):
    out = tmp_path / "m.stl"
    assert main(["mesh", "cubic", "--param", "n=2", "--style", "cnt", "--out", str(out), "--check"]) == 0
    text = capsys.readouterr().out
    rep = json.loads(text[text.index("{"):])
    line = next(s for s in text.splitlines() if s.startswith("volume:"))
    mesh, lattice, diff = (float(x) for x in re.search(
        r"mesh ([-\d.e+]+), lattice ([-\d.e+]+) .*difference ([-+\d.]+) %", line).groups())
    assert mesh == pytest.approx(rep["mesh_volume"], rel=1e-8) and lattice == pytest.approx(rep["lattice_volume"],
                                                                                          rel=1e-8)
    assert diff == pytest.approx(100 * (rep["mesh_volume"] / rep["lattice_volume"] - 1), abs=1e-3)
    assert main(["info", "cubic", "--param", "n=2", "--json"]) == 0
    assert rep["lattice_volume"] == json.loads(capsys.readouterr().out)["volume"]
    back = read_back(out)
    assert rep["triangles"] == len(back.faces) and rep["self_intersecting_pairs"] == 0
    assert rep["watertight"] and rep["winding_consistent"] and rep["euler_characteristic"] == back.euler_number
    assert rep["mesh_volume"] == pytest.approx(back.volume, rel=1e-9)


def test_an_stl_is_read_in_chunks(tmp_path):
    s = trimesh.creation.icosphere(3)
    both = trimesh.util.concatenate([s, s.copy().apply_translation([0.5, 0.2, 0.1])])  # self-intersecting
    path = tmp_path / "two.stl"
    export_mesh(both, path)
    chunks = list(file_triangles(path, chunk=1000))
    assert len(chunks) > 1 and all(c.dtype == np.float32 for c in chunks)
    back = read_back(path)
    assert np.array_equal(np.concatenate(chunks), np.asarray(back.vertices)[np.asarray(back.faces)])
    with SpillFiles(tmp_path) as blocks:
        rep = check_triangles(lambda: file_triangles(path, chunk=1000), block=2000, store=blocks)
        assert rep["blocks"] > 1 and not list(tmp_path.glob("ple-spill-*/*"))  # every block read back
    assert not list(tmp_path.glob("ple-spill-*"))
    assert rep["self_intersecting_pairs"] == len(self_intersections(back.vertices, back.faces)) > 0


@pytest.mark.parametrize("name, params", [("octet", {"n": 2}), ("warped", {"n": 3}), ("tmi_slab", {"nu": 2, "nv": 3})])
def test_monte_carlo_volume_counts_the_points_every_element_would(name, params):
    """The Monte Carlo estimate of ``--check`` (each element tests only the samples of its grid
    cells) counts exactly the sample points that some ball or beam, tested on every point, holds."""
    lat = load_lattice(name, params)
    samples, seed = 40_000, 2
    ev = lat.evaluate()
    lo = (ev.center - ev.radius[:, None]).min(axis=0)
    hi = (ev.center + ev.radius[:, None]).max(axis=0)
    p = np.random.default_rng(seed).uniform(lo, hi, size=(samples, 3))
    inside = (np.linalg.norm(p[:, None] - ev.center[None], axis=2) <= ev.radius).any(axis=1)
    for a, b in ev.beam_nodes:
        inside |= beam_distance(p, ev.center[a], ev.radius[a], ev.center[b], ev.radius[b]) <= 0
    box = float(np.prod(hi - lo))
    assert monte_carlo_volume(lat, None, samples, seed)[0] == inside.mean() * box
