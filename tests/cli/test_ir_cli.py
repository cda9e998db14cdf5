"""ple-lattice/1 files and the ple CLI (presets, info, ir, eval), including every bad-input path."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import reference_matrix
from ple.cli.main import main
from ple.model.ir import lattice_from_dict, lattice_to_dict
from ple.program.presets import preset_names
from ple.program.sources import load_lattice

KINDS = {
    "identity": {},
    "translation": {"vector": [0.5, -1.0, 2.0]},
    "rotation": {"angle": 0.285, "axis": [0, 0, 1], "point": [-1.555, 0.003, 0]},
    "scaling": {"factor": 1.187, "point": [-3.333, 0, 0]},
    "swirl": {"angle": 0.224, "axis": [0, 1, 0], "point": [10.872, 0, 0.039], "factor": 0.953},
    "screw": {"angle": 7.5, "axis": [1, 1, 0], "point": [1, 2, 3], "distance": 0.4},
}


def base_ir(**extra):
    data = {"format": "ple-lattice/1",
            "nodes": [{"id": "a", "center": [0, 0, 0], "radius": 0.1},
                      {"id": "b", "center": [0.5, 0.1, 0], "radius": 0.05}],
            "beams": [{"from": "a", "to": "a", "offset": [1, 0, 0]}, {"from": "a", "to": "b"},
                      {"from": 1, "to": "a", "offset": [0, 1, 1]}],
            "U": {"count": 3, "similarity": {"kind": "translation", "vector": [1, 0, 0]}},
            "V": {"count": 4, "matrix": [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]]},
            "W": {"count": 2, "similarity": {"kind": "swirl", **KINDS["swirl"]}}}
    data.update(extra)
    return data


def run_cli(*args) -> int:
    return main([str(a) for a in args])


@pytest.mark.parametrize("kind", list(KINDS))
def test_ir_resolves_each_kind_to_the_independent_matrix(tmp_path, kind):
    src = tmp_path / "l.json"
    src.write_text(json.dumps(base_ir(W={"count": 3, "similarity": {"kind": kind, **KINDS[kind]}})))
    out = tmp_path / "r.json"
    assert run_cli("ir", src, "--out", out) == 0
    got = np.array(json.loads(out.read_text())["W"]["matrix"])
    ref = reference_matrix(kind, **KINDS[kind])
    assert np.abs(got - ref).max() <= 1e-9 * max(1, np.abs(ref).max())


def test_cumulative_ir_resolves_to_the_root(tmp_path):
    src = tmp_path / "l.json"
    src.write_text(json.dumps(base_ir(U={"count": 5, "cumulative": True,
                                         "similarity": {"kind": "rotation", **KINDS["rotation"]}})))
    out = tmp_path / "r.json"
    assert run_cli("ir", src, "--out", out) == 0
    m = np.array(json.loads(out.read_text())["U"]["matrix"])
    assert np.allclose(np.linalg.matrix_power(m, 4), reference_matrix("rotation", **KINDS["rotation"]), atol=1e-12)


def test_eval_of_matrix_lattice_matches_matrix_powers(tmp_path, rng):
    from lattices import random_similarity_matrix
    mats = [random_similarity_matrix(rng) for _ in range(4)]
    data = base_ir(U={"count": 3, "matrix": mats[0].tolist()}, V={"count": 4, "matrix": mats[1].tolist()},
                   W={"count": 5, "matrix": mats[2].tolist()}, placement={"matrix": mats[3].tolist()})
    src, out = tmp_path / "l.json", tmp_path / "e.npz"
    src.write_text(json.dumps(data))
    assert run_cli("eval", src, "--region", "1:3,0:4,2:5", "--out", out) == 0
    z = np.load(out)
    assert set(z.files) == {"node_index", "center", "radius", "beam_index", "beam_nodes"}
    assert z["node_index"].shape == (2 * 4 * 3 * 2, 4) and z["beam_nodes"].shape[1] == 2
    for (i, j, k, n), c, r in zip(z["node_index"], z["center"], z["radius"]):
        m = mats[3] @ np.linalg.matrix_power(mats[2], k) @ np.linalg.matrix_power(mats[1], j) \
            @ np.linalg.matrix_power(mats[0], i)
        ref = (m @ np.append(data["nodes"][n]["center"], 1))[:3]
        assert np.abs(c - ref).max() <= 1e-9 * max(1, np.abs(ref).max())
        assert r == pytest.approx(data["nodes"][n]["radius"] * np.linalg.det(m[:3, :3]) ** (1 / 3), rel=1e-9)
    # beam rows point at the nodes their index names
    for (i, j, k, _p), (a, _b) in zip(z["beam_index"], z["beam_nodes"]):
        assert tuple(z["node_index"][a][:3]) == (i, j, k)


def test_ir_round_trip_canonical(tmp_path):
    lat = load_lattice("fig6_3")
    again = lattice_from_dict(json.loads(json.dumps(lattice_to_dict(lat, resolved=False))))
    assert np.allclose(again.evaluate().center, lat.evaluate().center, atol=1e-12)
    resolved = lattice_from_dict(json.loads(json.dumps(lattice_to_dict(lat, resolved=True))))
    assert np.allclose(resolved.evaluate().center, lat.evaluate().center, atol=1e-9)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["W"]["similarity"].update(axis=[0, 0, 0]), "W.similarity.*zero vector"),
    (lambda d: d["W"]["similarity"].update(factor=0), "W.similarity.*positive"),
    (lambda d: d["W"]["similarity"].update(factor=-1.5), "W.similarity.*positive"),
    (lambda d: d["V"].update(matrix=[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]), "V.matrix.*similarity"),
    (lambda d: d["U"].update(count=0), "U.count.*at least 1"),
    (lambda d: d["beams"][1].update(to="zz"), r"beams\[1\].to: unknown node id 'zz'"),
    (lambda d: d["nodes"][0].update(radius=float("nan")), r"nodes\[0\].radius"),
    (lambda d: d["nodes"][1].update(center=[0, 1]), r"nodes\[1\].center"),
    (lambda d: d["W"]["similarity"].update(kind="warp"), "W.similarity.kind"),
    (lambda d: d.update(format="ple-lattice/9"), "format"),
    (lambda d: d.update(colour="red"), "colour: unknown field"),
])
def test_bad_ir_exits_2_naming_the_field(tmp_path, capsys, mutate, message):
    data = base_ir()
    mutate(data)
    src, out = tmp_path / "bad.json", tmp_path / "out.json"
    src.write_text(json.dumps(data))
    assert run_cli("ir", src, "--out", out) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    import re
    assert re.search(message, err), err
    assert not out.exists()


def test_malformed_json(tmp_path, capsys):
    src = tmp_path / "bad.json"
    src.write_text('{"format": "ple-lattice/1", "nodes": [')
    assert run_cli("info", src) == 2
    assert "malformed JSON" in capsys.readouterr().err


@pytest.mark.parametrize("program, message", [
    ("def lattice():\n    raise RuntimeError('boom')\n", "program raised RuntimeError: boom"),
    ("def lattice(:\n", "syntax error"),
    ("x = 1\n", "must define a function lattice"),
    ("def lattice():\n    return 3\n", "must return a Lattice"),
    ("def lattice():\n    lat = Lattice()\n    lat.add_node(Pt(0,0,0), 0.1)\n"
     "    lat.set_u(3, Rotation(1, Vec(0,0,0), Pt(0,0,0)))\n    return lat\n", "zero vector"),
])
def test_bad_programs_exit_2(tmp_path, capsys, program, message):
    src, out = tmp_path / "p.py", tmp_path / "o.npz"
    src.write_text(program)
    assert run_cli("eval", src, "--out", out) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_params_and_their_errors(tmp_path, capsys):
    out = tmp_path / "e.npz"
    assert run_cli("eval", "cubic", "--param", "n=2", "--out", out) == 0
    assert len(np.load(out)["center"]) == 8
    assert run_cli("eval", "cubic", "--param", "n=two", "--out", out) == 2
    assert "parameter n" in capsys.readouterr().err
    assert run_cli("eval", "cubic", "--param", "size=2", "--out", out) == 2
    assert "unknown parameter" in capsys.readouterr().err
    assert run_cli("eval", "no_such_preset", "--out", out) == 2
    assert run_cli("eval", "cubic", "--region", "0:99,0:1,0:1", "--out", out) == 2
    assert "outside" in capsys.readouterr().err


def test_existing_output_survives_a_failed_run(tmp_path):
    out = tmp_path / "keep.npz"
    out.write_bytes(b"precious")
    assert run_cli("eval", "cubic", "--param", "n=0", "--out", out) == 2
    assert out.read_bytes() == b"precious"


def test_presets_and_info(capsys):
    assert run_cli("presets") == 0
    listed = capsys.readouterr().out
    for name in preset_names():
        assert name in listed
    for needed in ("cubic", "bcc", "fcc", "octet", "kagome", "fig6_3", "cylindrical", "warped"):
        assert needed in preset_names()
    assert run_cli("info", "fig6_3", "--json") == 0
    info = json.loads(capsys.readouterr().out)
    assert info["counts"] == [7, 12, 15] and info["nodes"] == 1260
    kinds = {k: v["kind"] for k, v in info["similarities"].items()}
    assert kinds == {"U": "scaling", "V": "rotation", "W": "swirl"}
    ev = load_lattice("fig6_3").evaluate()
    assert info["beams"] == len(ev.beam_nodes)
    assert np.allclose(info["bounds"]["min"], (ev.center - ev.radius[:, None]).min(0))


def test_console_script_has_no_traceback(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2")
    proc = subprocess.run([sys.executable, "-m", "ple.cli", "info", str(bad)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "malformed JSON" in proc.stderr
