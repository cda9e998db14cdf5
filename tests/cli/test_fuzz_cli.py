"""Fuzzing the CLI (issue 20): random IR mutations and random arguments end with exit 0 or 2,
never a traceback, and never leave a partial, temporary or destroyed file."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from ple.cli.main import main
from ple.io.files import TMP_TAG

BASE = {"format": "ple-lattice/1",
        "nodes": [{"id": "a", "center": [0, 0, 0], "radius": 0.2}, {"id": "b", "center": [0.5, 0.5, 0], "radius": 0.1}],
        "beams": [{"from": "a", "to": "b", "offset": [0, 0, 0]}, {"from": "a", "to": "a", "offset": [1, 0, 0]}],
        "U": {"count": 3, "similarity": {"kind": "translation", "vector": [1, 0, 0]}},
        "V": {"count": 2, "similarity": {"kind": "rotation", "angle": 0.3, "axis": [0, 0, 1], "point": [0, 0, 0]}},
        "W": {"count": 2, "cumulative": True, "matrix": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]]},
        "placement": {"similarity": {"kind": "scaling", "factor": 2, "point": [0, 0, 0]}}}

SETTINGS = settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)

leaf = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.sampled_from([10**400, -(10**30)]),
                 st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                 st.sampled_from(["a", "b", "translation", "swirl", "cone", "offest", "ple-lattice/1"]))
json_value = st.recursive(leaf, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                        st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                          max_leaves=12)


def _paths(x, prefix=()):
    yield prefix
    if isinstance(x, dict):
        for k, v in x.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _paths(v, prefix + (i,))


@st.composite
def mutated_ir(draw):
    data = json.loads(json.dumps(BASE))
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(data) if p]
        path = draw(st.sampled_from(paths))
        parent = data
        for key in path[:-1]:
            parent = parent[key]
        op = draw(st.sampled_from(["number", "number", "number", "replace", "delete", "add", "nest"]))
        if op == "number":  # a plausible or extreme number where a number is
            if isinstance(parent[path[-1]], (int, float)) and not isinstance(parent[path[-1]], bool):
                parent[path[-1]] = draw(st.one_of(st.floats(-3, 3), st.integers(-4, 6),
                                                  st.sampled_from([1e-300, 1e15, 1e99, 1e101, -0.0, 2**53 + 1])))
        elif op == "replace":
            parent[path[-1]] = draw(json_value)
        elif op == "delete":
            del parent[path[-1]]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["offest", "raduis", "count", "kind", "x", "meta"]))] = draw(json_value)
        elif op == "nest":
            parent[path[-1]] = [parent[path[-1]]] * draw(st.integers(1, 2))
        if not isinstance(data, dict) or not data:
            break
    return data


def _snapshot(folder: Path) -> dict:
    return {p.name: (p.read_bytes() if p.is_file() else None) for p in folder.iterdir()}


def _check_folder(folder: Path, before: dict, outputs: set[str]) -> None:
    after = _snapshot(folder)
    assert not [n for n in after if TMP_TAG in n], after.keys()
    for name, content in before.items():
        if name not in outputs:
            assert after.get(name, "gone") == content, name  # nothing the user had changed


@pytest.fixture(autouse=True)
def small_budget(monkeypatch):
    monkeypatch.setenv("PLE_MAX_MEMORY", "256M")  # anything big is refused by the budget, quickly


@SETTINGS
@given(data=mutated_ir(), command=st.sampled_from(["ir", "info", "eval"]))
def test_ir_mutations_exit_0_or_2_and_keep_files(data, command, capsys):
    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        src = folder / "l.json"
        src.write_text(json.dumps(data, allow_nan=True))
        out = folder / ("out.json" if command == "ir" else "out.npz")
        out.write_bytes(b"previous output")
        before = _snapshot(folder)
        args = [command, str(src)] + ([] if command == "info" else ["--out", str(out)])
        code = main(args)
        err = capsys.readouterr().err
        event(f"exit {code}")
        assert code in (0, 2), err
        if code == 2:
            assert len(err.strip().splitlines()) == 1, err
            assert out.read_bytes() == b"previous output"
        elif command == "ir":
            assert json.loads(out.read_text())["format"] == "ple-lattice/1"
        _check_folder(folder, before, {out.name})


TOKENS = {
    "--region": st.one_of(st.text(max_size=10), st.sampled_from(["0:2,0:2,0:2", "0:0,0:1,0:1", "-1:,:,:", "0:99,,",
                                                                  "0:2,0:2", "a:b,c:d,e:f", "0:10**9,0:1,0:1"])),
    "--param": st.one_of(st.sampled_from(["n=2", "n=0", "n=-3", "n=10000", "n=1e3", "cell=1e300", "cell=nan",
                                          "radius=0", "radius=-1", "radius=0.3", "x=1", "n"]),
                         st.text(max_size=10).map(lambda t: "n=" + t)),
    "--stencil": st.sampled_from(["edges", "edges:2", "corners:0", "edges:1e10", "faces:2x2", "checker:3:0",
                                  "nope", "layers:2:5", "user.npy", "data.npz"]),
    "--levels": st.sampled_from(["0", "1", "-1", "7", "x", "100"]),
    "--style": st.sampled_from(["cnt", "chocc", "refined", "balls-beams", "bad"]),
    "--segments": st.sampled_from(["3", "2", "16", "100000", "-5"]),
    "--queries": st.sampled_from(["q.npy", "data.npz", "user.txt", "missing.npy", "folder", "user.npy"]),
    "--coarse": st.sampled_from(["cubic:n=2,cell=5", "cubic", "nope", "cubic:radius=-1", "../cubic"]),
    "--max-memory": st.sampled_from(["1G", "1K", "x", "64M", "-2G"]),
    "--timeout": st.sampled_from(["5", "0", "-1", "nan", "inf"]),
}
OUTS = ["new.json", "new.npz", "new.stl", "new.glb", "new.3mf", "user.txt", "folder", "user.npy", "chunks",
        "missing/x.json", "new.ply", "new"]
COMMANDS = {"ir": ["--param"], "info": ["--param"], "eval": ["--param", "--region"],
            "filter": ["--param", "--region", "--stencil", "--coarse"], "lil": ["--param", "--coarse", "--region"],
            "mesh": ["--param", "--region", "--style", "--levels", "--segments"], "biq": ["--param", "--queries"]}


@st.composite
def cli_args(draw):
    command = draw(st.sampled_from(sorted(COMMANDS)))
    source = draw(st.sampled_from(["cubic", "cubic", "octet", "l.json", "l.json", "nope", "folder", "user.txt",
                                   "../x/cubic"]))
    args = [command, source]
    for flag in draw(st.lists(st.sampled_from(COMMANDS[command] + ["--max-memory", "--timeout"]), max_size=3)):
        args += [flag, draw(TOKENS[flag])]
    if command == "mesh" and "--param" not in args and source in ("cubic", "octet"):
        args += ["--param", "n=2"]
    if command in ("filter", "lil") and not ({"--stencil", "--coarse"} & set(args)):
        args += ["--stencil", "edges:2"] if command == "filter" else ["--coarse", "cubic:n=2,cell=5"]
    if command == "biq" and "--queries" not in args:
        args += ["--queries", "q.npy"]
    if command != "info":
        fitting = {"ir": "new.json", "eval": "new.npz", "filter": "new.npz", "lil": "chunks", "mesh": "new.stl",
                   "biq": "new.json"}[command]
        args += ["--out", draw(st.sampled_from([fitting, fitting, fitting] + OUTS))]
    return args


@SETTINGS
@given(args=cli_args())
def test_random_arguments_exit_0_or_2_and_keep_files(args, capsys):
    import numpy as np

    with tempfile.TemporaryDirectory() as d:
        folder = Path(d)
        (folder / "l.json").write_text(json.dumps(BASE))
        (folder / "user.txt").write_text("the user's file")
        (folder / "folder").mkdir()
        (folder / "folder" / "notes.txt").write_text("notes")
        np.save(folder / "q.npy", np.array([[0.5, 0.5, 0.5, 0.3]]))
        np.save(folder / "user.npy", np.ones((2, 2, 2), bool))
        np.savez(folder / "data.npz", a=np.zeros(3))
        before = _snapshot(folder)
        cwd = os.getcwd()
        os.chdir(folder)
        try:
            code = main(args)
        except SystemExit as exc:  # argparse: a usage error
            code = exc.code
        finally:
            os.chdir(cwd)
        err = capsys.readouterr().err
        event(f"{args[0]} exit {code}")
        assert code in (0, 2), (args, err)
        assert "Traceback" not in err, err
        assert _snapshot(folder / "folder") == {"notes.txt": b"notes"}
        outs = {a for a in args if a.startswith("new")} | ({"chunks", "user.txt", "user.npy"} if code == 0 else set())
        _check_folder(folder, before, outs)
