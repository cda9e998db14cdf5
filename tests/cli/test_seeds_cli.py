"""The commands on lattices placed by group maps (TMI, Möbius) and on a rectified warp:
eval, info, mesh --check, biq (naive path, named), ir (refused), bench seeds (small)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from ple.cli.main import main
from ple.program.sources import load_lattice

PRESETS = Path(__file__).resolve().parents[2] / "presets"


def test_eval_info_mesh_biq_on_a_tmi_slab(tmp_path, capsys):
    src = str(PRESETS / "tmi_slab.py")
    lat = load_lattice(src, {"nu": 3, "nv": 3})
    out = tmp_path / "e.npz"
    assert main(["eval", src, "--param", "nu=3", "--param", "nv=3", "--out", str(out)]) == 0
    with np.load(out) as z:
        c, r = lat.node_balls(z["node_index"])
        assert np.allclose(z["center"], c) and np.allclose(z["radius"], r) and len(z["beam_nodes"]) == 24
    capsys.readouterr()
    assert main(["info", src, "--param", "nu=3", "--param", "nv=3", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["group_map"]["kind"] == "Möbius" and "similarities" not in info
    assert info["nodes"] == 16 and info["volume"] > 0 and "per-hub" in info["area_method"]
    mesh = tmp_path / "m.stl"
    assert main(["mesh", src, "--param", "nu=3", "--param", "nv=3", "--out", str(mesh), "--check"]) == 0
    text = capsys.readouterr().out
    report = json.loads(text[text.index("{"):])
    assert report["watertight"] and abs(report["relative_volume_error"]) < 0.01
    q = tmp_path / "q.npy"
    np.save(q, np.array([[0.0, 0.0, 0.0, 0.2], [2.0, 2.0, 0.0, 0.1]]))
    res = tmp_path / "b.json"
    assert main(["biq", src, "--param", "nu=3", "--param", "nv=3", "--queries", str(q), "--out", str(res)]) == 0
    assert "path mobius (" in capsys.readouterr().out  # the pre-image RangeFinder (thesis §11.2.1)
    hits = json.loads(res.read_text())["queries"]
    ev = lat.evaluate()
    d = np.linalg.norm(ev.center - [0, 0, 0], axis=1) - ev.radius - 0.2
    assert sorted(map(tuple, hits[0]["nodes"])) == sorted(map(tuple, ev.node_index[d <= 0].tolist()))
    assert main(["ir", src, "--param", "nu=3", "--param", "nv=3", "--out", str(tmp_path / "x.json")]) == 0


def test_bench_seeds_runs_small(capsys):
    assert main(["bench", "seeds", "--queries", "3", "--naive-queries", "1", "--skip-lil", "--skip-fig93"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {r["lattice"] for r in out["table_7_2"]} == {"thesis_regular", "thesis_cylindrical", "thesis_warped"}
    for row in out["table_7_2"]:
        assert all(v.get("same_hits_as_best_path", True) for v in row["ours"].values())
    assert set(out["table_7_2"][0]["ours"]) == {"1", "u", "uv", "naive"}
    assert len(out["fig_21"]["rows"]) == 3


def test_thesis_lil_method_draws_every_valid_fine_beam_once():
    """Both end nodes of every valid fine beam (thesis §7.4: two BIQs per beam), against the evaluation."""
    from ple.bench.lil import fine_beam_ends

    fine = load_lattice("thesis_regular", {"n": 4})
    idx, beams = fine_beam_ends(fine, 10**6, np.random.default_rng(0))
    ev = fine.evaluate()
    assert beams == fine.beam_count() == len(ev.beam_nodes) and len(idx) == 2 * beams
    ni = ev.node_index
    want = {tuple(sorted((tuple(ni[a]), tuple(ni[b])))) for a, b in ev.beam_nodes}
    got = {tuple(sorted((tuple(a), tuple(b)))) for a, b in zip(idx[:beams].tolist(), idx[beams:].tolist())}
    assert got == want


def test_thesis_lil_method_rows_agree_across_paths():
    """Every path of the thesis-method LiL finds the same queries with a hit (one worker, small sample)."""
    from ple.bench.lil import thesis_method_rows

    rows = thesis_method_rows(300, 300, 1, 3, full=())
    assert [r["case"].split()[0] for r in rows] == ["regular", "cylindrical", "semi-regular", "semi-regular"]
    for row in rows:
        hits = {p: v["queries_with_a_hit"] for p, v in row["ours"].items()}
        assert len(set(hits.values())) == 1, hits
        assert row["biqs"] == 2 * row["fine_beams"]


def test_hier_lil3_reaches_fig_9_3s_size_and_its_counts_grow_with_the_radii():
    """The slider takes n = 138 (thesis Fig. 9.3: 138³ groups); a larger medium or coarse radius
    never keeps fewer beams, which is what the bisections of ``fig_9_3`` rest on."""
    from ple.bench.seeds import fig_9_3

    assert load_lattice("hier_lil3", {"n": 138}).beam_count() == 3 * 137 * 138 * 138
    out = fig_9_3(n=17, steps=2)
    counts = [k for _, k in sorted(out["medium_radius_search"]["evaluations"])]
    assert counts == sorted(counts) and counts[0] < counts[-1] <= out["fine_beams"]
    counts = [k for _, k in sorted(out["coarse_radius_search"]["evaluations"])]
    assert counts == sorted(counts)
