"""``ple check``: design rules against independent computations (union–find components, degrees,
beam diameters and slenderness from the evaluated arrays), exit codes 0 / 1 / 2, JSON report."""

from __future__ import annotations

import json

import numpy as np
import pytest
from ple.cli.main import main
from ple.measure.check import check_lattice, is_clean
from ple.program.sources import load_lattice

PROGRAM = '''
def lattice(n: int = 6, radius: float = 0.1, lone: float = 0.0, cross: bool = False, keep: str = "edges"):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    if cross:
        lat.add_beam(a, a, 1, 1, 0)
        lat.add_beam(a, a, -1, 1, 0)
    if lone:
        lat.add_node(Pt(0.5, 0.5, 0.5), lone)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    if keep:
        lat.set_filter(Stencil.named(keep, 3))
    return lat
'''


@pytest.fixture
def program(tmp_path):
    path = tmp_path / "grid.py"
    path.write_text(PROGRAM)
    return str(path)


def _json(capsys, *args) -> tuple[int, dict]:
    code = main(["check", *args, "--json"])
    return code, json.loads(capsys.readouterr().out)


def _components(n, edges):
    parent = list(range(n))

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for a, b in edges:
        parent[find(a)] = find(b)
    return len({find(x) for x in range(n)})


def test_clean_preset_passes(capsys):
    code, rep = _json(capsys, "cubic")
    assert code == 0 and rep["ok"] and rep["rules"]["clean"]["count"] == 0
    assert rep["rules"]["components"]["count"] == 1
    assert main(["check", "cubic"]) == 0
    assert "ok   clean" in capsys.readouterr().out


def test_rules_match_independent_computations(capsys, program):

    params = ["--param", "keep=edges", "--param", "lone=0.05"]
    code, rep = _json(capsys, program, *params, "--min-feature", "0.25", "--max-slenderness", "4")
    lat = load_lattice(program, {"keep": "edges", "lone": "0.05"})
    ev = lat.evaluate()
    a, b = ev.beam_nodes.T
    diam = 2 * np.minimum(ev.radius[a], ev.radius[b])
    slender = np.linalg.norm(ev.center[b] - ev.center[a], axis=1) / diam
    degree = np.bincount(ev.beam_nodes.reshape(-1), minlength=len(ev.radius))
    r = rep["rules"]
    assert code == 1 and not rep["ok"] and rep["filtered"]
    assert rep["nodes"] == len(ev.radius) and rep["beams"] == len(ev.beam_nodes)
    assert r["thinnest_beam"]["value"] == pytest.approx(diam.min())
    assert r["thinnest_beam"]["count"] == np.sum(diam < .25)
    assert r["slenderness"]["value"] == pytest.approx(slender.max())
    assert r["slenderness"]["count"] == np.sum(slender > 4)
    assert r["dangling_beams"]["count"] == np.sum(degree == 1)
    assert r["isolated_balls"]["count"] == np.sum(degree == 0) > 0
    assert r["components"]["count"] == _components(len(ev.radius), ev.beam_nodes.tolist()) > 1
    for w in r["isolated_balls"]["worst"]:
        assert tuple(w["ball"]) in {tuple(x) for x in ev.node_index[degree == 0].tolist()}


def test_unclean_lattice_fails_with_offenders(capsys, program):
    code, rep = _json(capsys, program, "--param", "cross=1", "--param", "keep=")
    clean = rep["rules"]["clean"]
    assert code == 1 and not clean["ok"] and clean["value"]["beam_beam"] == 5 * 5 * 6
    assert clean["worst"] and clean["worst"][0]["kind"] == "beam_beam"
    assert is_clean(load_lattice(program, {"cross": "1", "keep": ""})) is False
    assert is_clean(load_lattice(program, {"keep": ""})) is True
    code = main(["check", program, "--param", "cross=1", "--param", "keep=", "--region", "0:2,0:3,0:2"])
    out = capsys.readouterr().out
    assert code == 1 and "FAIL clean" in out and "beam_beam" in out


def test_gap_rule(capsys):
    lat = load_lattice("cubic")
    gap = 1 - 2 * float(lat.template_radii[0])  # parallel struts one cell apart
    rep = check_lattice(lat, min_feature=gap + 0.01)
    assert rep["rules"]["smallest_gap"]["value"] == pytest.approx(gap) and not rep["rules"]["smallest_gap"]["ok"]
    assert check_lattice(lat, min_feature=gap - 0.01)["rules"]["smallest_gap"]["ok"]


@pytest.mark.parametrize("args", [["cubic", "--min-feature", "-1"], ["cubic", "--max-slenderness", "0"],
                                  ["no_such_lattice"], ["cubic", "--region", "0:99,0:1,0:1"]])
def test_bad_input_exits_2(capsys, args):
    assert main(["check", *args]) == 2
    assert "error" in capsys.readouterr().err


def test_components_without_scipy_equal_scipy():
    """The numpy fallback (min-label hooking, for Blender's Python) partitions like scipy."""
    from ple.measure.check import _min_labels
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(1)
    for _ in range(100):
        n, m = int(rng.integers(1, 300)), int(rng.integers(0, 400))
        e = rng.integers(0, n, (m, 2))
        label = _min_labels(n, e)
        count, want = connected_components(coo_matrix((np.ones(m), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
        assert len(set(zip(want.tolist(), label.tolist()))) == count == len(np.unique(label))
