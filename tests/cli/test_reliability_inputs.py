"""Bad inputs of issue 20, each reproduced: exit 2 with one line naming the input, never a
traceback, never exit 0 with garbage (docs/reliability.md). In-process through ``ple.cli.main``."""

from __future__ import annotations

import json
import math
import os
import threading

import numpy as np
import pytest
from ple.cli.main import main
from ple.errors import PleError
from ple.model.schema import SCHEMA, check_ir, nearest
from ple.program.sources import load_lattice


def base_ir(**extra) -> dict:
    ir = {"format": "ple-lattice/1",
          "nodes": [{"id": "a", "center": [0, 0, 0], "radius": 0.1}, {"id": "b", "center": [0.5, 0, 0], "radius": 0.1}],
          "beams": [{"from": "a", "to": "b", "offset": [0, 0, 0]}, {"from": "a", "to": "a", "offset": [1, 0, 0]}],
          "U": {"count": 3, "similarity": {"kind": "translation", "vector": [1, 0, 0]}}}
    ir.update(extra)
    return ir


def cli(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def expect_error(capsys, needle: str, *args) -> str:
    code, out, err = cli(capsys, *args)
    assert code == 2, (code, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in err, err
    return err


def write_ir(tmp_path, data, name="l.json") -> str:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return str(path)


# ----- the strict loader -------------------------------------------------------------------------
def test_base_ir_loads(tmp_path, capsys):
    code, out, _ = cli(capsys, "info", write_ir(tmp_path, base_ir()))
    assert code == 0 and "3 x 1 x 1" in out


@pytest.mark.parametrize("mutate, needle", [
    (lambda d: d["beams"][0].update(offest=[1, 0, 0]), "beams[0].offest: unknown field (did you mean 'offset'?)"),
    (lambda d: d["nodes"][1].update(raduis=1), "nodes[1].raduis: unknown field (did you mean 'radius'?)"),
    (lambda d: d["U"]["similarity"].update(vectr=[1, 0, 0]), "U.similarity.vectr: unknown field"),
    (lambda d: d["U"].update(cnt=3), "U.cnt: unknown field (did you mean 'count'?)"),
    (lambda d: d.update(descripton="x"), "descripton: unknown field (did you mean 'description'?)"),
    (lambda d: d["U"]["similarity"].update(factor=2), "U.similarity.factor: not a parameter of a translation"),
    (lambda d: d["beams"][0].update(to=None), "beams[0].to: expected a node id"),
    (lambda d: d.update(beams=None), "beams: expected a list"),
    (lambda d: d.update(beams=7), "beams: expected a list"),
    (lambda d: d["beams"][0].update(offset=[2**62, 0, 0]), "beams[0].offset[0]: must be at most"),
    (lambda d: d["beams"][0].update(offset=[10**20, 0, 0]), "beams[0].offset[0]: must be at most"),
    (lambda d: d["beams"][0].update(offset=[0, -(10**20), 0]), "beams[0].offset[1]: must be at least"),
    (lambda d: d["U"]["similarity"].update(kind=["translation"]), "U.similarity.kind: unknown kind"),
    (lambda d: d["U"]["similarity"].update(kind="translaton"), "did you mean 'translation'?"),
    (lambda d: d.update(U={"count": 3, "similarity": {"kind": "scaling", "factor": 1e308, "point": [0, 0, 0]}}),
     "U.similarity.factor: must lie in"),
    (lambda d: d.update(U={"count": 3, "similarity": {"kind": "translation", "vector": [1e200, 0, 0]}}),
     "U.similarity.vector[0]: must lie in"),
    (lambda d: d.update(U={"count": 3, "similarity": {"kind": "rotation", "angle": 1, "axis": [1e308, 1e308, 0],
                                                       "point": [0, 0, 0]}}), "U.similarity.axis[0]"),
    (lambda d: d.update(U={"count": 200, "similarity": {"kind": "scaling", "factor": 1e3, "point": [0, 0, 0]}}),
     "overflows: the powers of U"),
    (lambda d: d["nodes"][0].update(radius=float("nan")), "nodes[0].radius: must be finite"),
    (lambda d: d["U"].update(count=True), "U.count: expected an integer"),
    (lambda d: d.update(placement={}), "placement: give one of"),
    (lambda d: d.update(meta={"x": 1}, U={"count": 3, "matrix": [[1, 0, 0, 0]] * 3}), "U.matrix: expected 4 rows"),
])
def test_loader_rejects_with_path_and_nearest_name(tmp_path, capsys, mutate, needle):
    data = base_ir()
    mutate(data)
    expect_error(capsys, needle, "info", write_ir(tmp_path, data))


def test_the_filter_field_is_left_to_the_filter_reader(tmp_path, capsys):
    """main's IR carries an optional top-level "filter" (ple.filters.ir): the strict schema lets it
    through, and the filter reader names its own mistakes."""
    keep = {"stencil": {"shape": [2, 1, 1], "cells": [1, 0]}}
    code, out, err = cli(capsys, "info", write_ir(tmp_path, base_ir(filter=keep)), "--json")
    assert code == 0, err
    info = json.loads(out)
    assert info["filtered"] and info["nodes"] == 4 and info["program_nodes"] == 6
    expect_error(capsys, "filter.kind: unknown filter", "info", write_ir(tmp_path, base_ir(filter={"kind": "stencl"})))
    expect_error(capsys, "fliter: unknown field (did you mean 'filter'?)", "info",
                 write_ir(tmp_path, base_ir(fliter=keep)))


@pytest.mark.parametrize("becots, needle", [
    ({"corners": [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], "counts": [2, 2], "branch": "ab"}, "becots.branch"),
    ({"corners": [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], "counts": [2, 2], "branch": [float("nan"), 0]},
     "becots.branch[0]"),
    ({"corners": [[0, 0, 0], [0, 1, 0], [1, 1, 0]], "counts": [2, 2]}, "becots.corners"),
    ({"corners": [[0, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0]], "counts": [2, 2], "stack": {"layers": 1}},
     "becots.stack.nodes_per_layer: missing"),
])
def test_becots_fields_are_checked(tmp_path, capsys, becots, needle):
    data = base_ir(becots=becots)
    del data["U"]
    expect_error(capsys, needle, "info", write_ir(tmp_path, data))


def test_deep_nesting_huge_integers_and_bad_utf8(tmp_path, capsys):
    expect_error(capsys, "nested deeper", "info", write_ir(tmp_path, "[" * 100_000 + "]" * 100_000))
    nested: list = []
    for _ in range(40):  # 40 levels: a valid Python object, deeper than the schema's 32
        nested = [nested]
    expect_error(capsys, "nested deeper", "info", write_ir(tmp_path, base_ir(meta=nested)))
    digits = json.dumps(base_ir()).replace('"count": 3', '"count": ' + "9" * 5000)
    expect_error(capsys, "unreadable JSON", "info", write_ir(tmp_path, digits))
    (tmp_path / "bad.json").write_bytes(b'{"format": "ple-lattice/1", "description": "\xff\xfe"}')
    expect_error(capsys, "not UTF-8", "info", tmp_path / "bad.json")


def test_folders_and_fifos_are_named_as_such(tmp_path, capsys):
    (tmp_path / "d.json").mkdir()
    expect_error(capsys, "is a folder", "info", tmp_path / "d.json")
    (tmp_path / "p.py").mkdir()
    expect_error(capsys, "is a folder", "info", tmp_path / "p.py")
    os.mkfifo(tmp_path / "f.json")
    expect_error(capsys, "not a regular file", "info", tmp_path / "f.json")  # and does not block
    expect_error(capsys, "no such", "info", tmp_path / "missing.json")


def test_preset_names_cannot_leave_the_presets_folder(tmp_path, capsys, monkeypatch):
    marker = tmp_path / "ran"
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "prog.py").write_text(f"open({str(marker)!r}, 'w')\ndef lattice():\n    return None\n")
    monkeypatch.chdir(tmp_path / "x")
    for name in ("../x/prog", "../../" + str(tmp_path)[1:] + "/x/prog", str(tmp_path / "x" / "prog"), ".hidden"):
        expect_error(capsys, "neither a .py program", "info", name)
    assert not marker.exists()


def test_schema_names_every_key_it_knows():
    assert nearest("offest", SCHEMA["beam"]) == " (did you mean 'offset'?)"
    check_ir(base_ir())
    with pytest.raises(PleError, match="nodes: missing"):
        check_ir({"format": "ple-lattice/1"})


# ----- numeric inputs of the commands -------------------------------------------------------------
def test_npz_and_huge_header_npy_inputs(tmp_path, capsys):
    np.savez(tmp_path / "a.npz", q=np.zeros((2, 4)))
    os.rename(tmp_path / "a.npz", tmp_path / "z.npy")
    huge = tmp_path / "h.npy"
    with open(huge, "wb") as fh:
        fh.write(b"\x93NUMPY\x02\x00" + (200_000).to_bytes(4, "little") + b"{" + b" " * 199_998 + b"\n")
    corners = "0,0,0 0,1,0 1,1,0 1,0,0"
    for path in (tmp_path / "z.npy", huge):
        expect_error(capsys, "cannot read a .npy array", "biq", "cubic", "--queries", path,
                     "--out", tmp_path / "h.json")
        expect_error(capsys, "cannot read a .npy array", "filter", "cubic", "--stencil", path,
                     "--out", tmp_path / "f.npz")
        expect_error(capsys, "cannot read a .npy array", "becots", "map", "--corners", corners, "--uv", path,
                     "--out", tmp_path / "m.npy")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.npy", "z.npy"]


@pytest.mark.parametrize("stencil", ["edges:1e10", "edges:10000000000", "corners:100000x100000x100000"])
def test_huge_stencils(tmp_path, capsys, stencil):
    expect_error(capsys, "stencil", "filter", "cubic", "--stencil", stencil, "--out", tmp_path / "f.npz")


def test_becots_numbers(tmp_path, capsys):
    np.save(tmp_path / "uv.npy", np.array([[1e300, 1e300], [0.5, 0.5]]))
    np.save(tmp_path / "p.npy", np.zeros((2, 3)))
    corners = "0,0,0 0,1e10,0 1e10,1e10,0 1e10,0,0"
    expect_error(capsys, "non-finite point", "becots", "map", "--corners", corners, "--uv", tmp_path / "uv.npy",
                 "--out", tmp_path / "m.npy")
    expect_error(capsys, "--tol nan", "becots", "inverse", "--corners", "0,0,0 0,1,0 1,1,0 1,0,0",
                 "--points", tmp_path / "p.npy", "--out", tmp_path / "i.json", "--tol", "nan")
    for radius in ("inf", "nan", "-1", "1e308"):
        expect_error(capsys, "--radius", "becots", "connectors", "becots_constant_radius", "--radius", radius,
                     "--out", tmp_path / "c")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.npy", "uv.npy"]


@pytest.mark.parametrize("args, needle", [
    (["info", "cubic", "--param", "cell=1e300"], "overflows"),
    (["info", "cubic", "--param", "cell=1e200"], "overflows"),
    (["eval", "cubic", "--param", "cell=1e300", "--out", "x.npz"], "overflows"),
    (["lil", "cubic", "--coarse", "cubic:radius=1e308"], "overflows"),
    (["lil", "cubic", "--coarse", "cubic:cell=1e300"], "overflows"),
    (["filter", "cubic", "--stencil", "edges", "--param", "radius=1e120", "--out", "x.npz"], "overflows"),
    (["bench", "mesh", "--big", "-1"], "--big -1"),
    (["batch", "cubic", "--param", "n=1:3:1000000000", "--out", "b"], "at most 10,000"),
    (["batch", "cubic", "--param", "n=1:3:100", "--param", "radius=0.1:0.2:101", "--out", "b"], "10,100 variants"),
])
def test_garbage_and_overflow_are_errors(tmp_path, capsys, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    expect_error(capsys, needle, *args)
    assert list(tmp_path.iterdir()) == []


def test_axis_of_huge_components_keeps_its_direction():
    from ple.algebra.similarity import Rotation

    s = Rotation(0.5, [1e308, 1e308, 0], [0, 0, 0])
    assert np.allclose(s.axis, [math.sqrt(0.5), math.sqrt(0.5), 0])
    assert s.kind == "rotation"


def test_translation_of_1e200_is_not_nan():
    from ple.algebra.similarity import Translation

    s = Translation([1e200, 0, 0])
    assert s.distance == pytest.approx(1e200) and np.allclose(s.axis, [1, 0, 0])


def test_info_of_a_huge_lattice_answers_counts_kinds_and_bounds(capsys):
    code, out, err = cli(capsys, "info", "cubic", "--param", "n=10000", "--json")
    info = json.loads(out)
    assert code == 0 and info["groups"] == 10**12 and info["beams"] == 3 * 10**8 * 9999
    assert info["bounds"]["exact"] and info["bounds"]["max"] == pytest.approx([9999.1] * 3)
    assert info["bounds"]["min"] == pytest.approx([-0.1] * 3)


def test_info_bounds_marked_approximate_when_sampled():
    from ple.algebra.similarity import Rotation
    from ple.algebra.vectors import Pt, Vec
    from ple.model.budget import fast_bounds
    from ple.model.lattice import Lattice

    lat = Lattice()
    lat.add_node(Pt(1, 0, 0), 0.1)
    lat.set_u(3000, Rotation(0.001, Vec(0, 0, 1), Pt(0, 0, 0)))
    lat.set_v(3000, Rotation(0.0007, Vec(0, 0, 1), Pt(0, 0, 0)))  # angles 0 .. 5.1 rad: a circle past 3π/2
    lo, hi, exact = fast_bounds(lat)
    assert not exact  # 9·10^6 rotated groups: sampled
    true_lo, true_hi = np.array([-1.1, -1.1, -0.1]), np.array([1.1, 1.1, 0.1])  # the circle of radius 1, balls 0.1
    assert np.all(lo >= true_lo - 1e-12) and np.all(hi <= true_hi + 1e-12)  # samples lie inside
    assert np.allclose(lo, true_lo, atol=1e-4) and np.allclose(hi, true_hi, atol=1e-4)
    small = load_lattice("thesis_warped", {"n": 20})
    lo, hi, exact = fast_bounds(small)
    assert exact and np.allclose((lo, hi), small.bounds())


def test_biq_count_matches_listing_and_huge_queries_ask_for_it(tmp_path, capsys):
    q = np.array([[2, 2, 2, 1.3], [5, 5, 5, 0.2]])
    np.save(tmp_path / "q.npy", q)
    assert cli(capsys, "biq", "cubic", "--queries", tmp_path / "q.npy", "--out", tmp_path / "l.json")[0] == 0
    assert cli(capsys, "biq", "cubic", "--queries", tmp_path / "q.npy", "--out", tmp_path / "c.json", "--count")[0] == 0
    listed = json.loads((tmp_path / "l.json").read_text())["queries"]
    counted = json.loads((tmp_path / "c.json").read_text())["queries"]
    assert counted == [{"nodes": len(x["nodes"]), "beams": len(x["beams"])} for x in listed]
    np.save(tmp_path / "big.npy", np.array([[0, 0, 0, 1e9]]))
    expect_error(capsys, "use --count", "biq", "cubic", "--param", "n=10000", "--queries", tmp_path / "big.npy",
                 "--out", tmp_path / "h.json")


def test_fifo_as_query_file_does_not_block(tmp_path, capsys):
    os.mkfifo(tmp_path / "q.npy")
    t = threading.Timer(20, lambda: open(tmp_path / "q.npy", "wb").close())  # unblocks a wrong open()
    t.start()
    try:
        expect_error(capsys, "not a regular file", "biq", "cubic", "--queries", tmp_path / "q.npy",
                     "--out", tmp_path / "h.json")
    finally:
        t.cancel()
