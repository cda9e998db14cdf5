"""The ple-clg/1 loader: every bad file exits 2 with one line naming the field; programs define clg()."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from ple.clg.ir import clg_from_dict, clg_to_dict
from ple.clg.query import compiled
from ple.cli.main import main
from ple.program.clg_sources import load_clg

ROOT = Path(__file__).resolve().parents[2]
SHELLED = json.loads((ROOT / "presets" / "clg" / "shelled.json").read_text())


def nested(depth: int) -> dict:
    out = copy.deepcopy(SHELLED)
    for _ in range(depth - 1):
        outer = copy.deepcopy(SHELLED)
        outer["materials"] = {"m": {"replace": out, "frame": "beam"}}
        outer["chunks"]["X"]["union"][1]["beam"]["material"] = "m"
        out = outer
    return out


def mutate(path: str, value):
    data = copy.deepcopy(SHELLED)
    keys = path.split("/")
    obj = data
    for k in keys[:-1]:
        obj = obj[int(k)] if isinstance(obj, list) else obj[k]
    last = keys[-1]
    if value is KeyError:
        del obj[last]
    elif isinstance(obj, list):
        obj[int(last)] = value
    else:
        obj[last] = value
    return data


BAD = [
    (mutate("solid", {"difference": ["X", "Z"]}), "solid.difference[1]", "unknown chunk"),
    (mutate("chunks/X/union/0/ball/node", [0, 0, 0, "b"]), "chunks.X.union[0].ball.node", "unknown node"),
    (mutate("chunks/X/union/0/ball/node", [0, 0, 0, 5]), "chunks.X.union[0].ball.node", "unknown node"),
    (mutate("chunks/X/union/1/beam/material", "steel"), "chunks.X.union[1].beam.material", "unknown material"),
    (mutate("chunks/Y", {"xor": []}), "chunks.Y.xor", "unknown operator"),
    (mutate("solid", {"xor": ["X", "Y"]}), "solid.xor", "unknown operator"),
    (mutate("chunks/X/union/0/ball/scale", 0), "chunks.X.union[0].ball.scale", "> 0"),
    (mutate("chunks/X/union/1/beam/scale", [1, -2]), "chunks.X.union[1].beam.scale[1]", "> 0"),
    (mutate("chunks/Y", {"hollow_beam": {"from": [0, 0, 0, 0], "to": [1, 0, 0, 0], "scale": [1, 1], "hollow": 1.0}}),
     "chunks.Y.hollow_beam.hollow", "(0, 1)"),
    (mutate("chunks/Y", {"hollow_beam": {"from": [0, 0, 0, 0], "to": [1, 0, 0, 0], "scale": [1, 1], "hollow": 0}}),
     "chunks.Y.hollow_beam.hollow", "(0, 1)"),
    (mutate("chunks/Y", {"connector": {"node": [0, 0, 0, 0], "outer": 1, "inner": 2, "reach": 3}}),
     "chunks.Y.connector.inner", "smaller"),
    (mutate("pattern/nodes/0/radius", -1), "pattern.nodes[0].radius", "positive"),
    (mutate("format", "ple-clg/2"), "format", "ple-clg/1"),
    (mutate("pattern", KeyError), "pattern", "missing"),
    (mutate("chunks/X/union/1/beam/from", [0, 0.5, 0, 0]), "chunks.X.union[1].beam.from", "integer"),
    (mutate("colour", 1), "colour", "unknown field"),
    (nested(9), "replace", "nesting deeper than 8"),
]


@pytest.mark.parametrize("data, field, words", BAD)
def test_bad_files_exit_2_naming_the_field(tmp_path, capsys, data, field, words):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    assert main(["clg", "info", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert field in err and words in err, err


def test_nesting_of_eight_is_fine():
    clg = clg_from_dict(nested(8))
    assert clg.depth == 8


def test_round_trip_keeps_membership():
    clg = clg_from_dict(SHELLED)
    again = clg_from_dict(json.loads(json.dumps(clg_to_dict(clg))))
    p = np.random.default_rng(0).uniform(-0.5, 4, (3000, 3))
    assert np.array_equal(compiled(clg).pmc(p), compiled(again).pmc(p))


def test_program_and_params(tmp_path):
    prog = tmp_path / "c.py"
    prog.write_text('"""A test CLG."""\n\n'
                    "def clg(r: Range(0.05, 0.3) = 0.1, n: Range(1, 9) = 3):\n"
                    "    lat = Lattice()\n"
                    "    a = lat.add_node(Pt(0, 0, 0), r)\n"
                    "    lat.add_beam(a, a, 1, 0, 0)\n"
                    "    lat.set_u(n, Translation(Vec(1, 0, 0)))\n"
                    "    return CLG(lat, {'A': HollowBeam(0, (1, 0, 0, 0), (1, 1), 0.5)}, 'A')\n")
    clg = load_clg(str(prog), ["r=0.2", "n=4"])
    assert clg.pattern.counts == (4, 1, 1)
    comp = compiled(clg)
    # the hollow beam: inside the wall, not in the cavity, not beyond the last copy's end
    assert comp.pmc([[0.5, 0.0, 0.15]])[0] and not comp.pmc([[0.5, 0, 0]])[0]
    assert not comp.pmc([[4.5, 0, 0.15]])[0] and comp.pmc([[3.5, 0, 0.15]])[0]
    bad = tmp_path / "b.py"
    bad.write_text("def lattice():\n    return None\n")
    with pytest.raises(Exception, match="must define a function clg"):
        load_clg(str(bad))


def test_non_commuting_pattern_is_accepted(tmp_path, capsys):
    """U and V do not commute: the copies use the lattice's own nodes (ple.clg.steady), no refusal."""
    data = copy.deepcopy(SHELLED)
    data["pattern"]["V"] = {"count": 2, "similarity": {"kind": "rotation", "angle": 0.5, "axis": [0, 0, 1],
                                                       "point": [0, 0, 0]}}
    path = tmp_path / "nc.json"
    path.write_text(json.dumps(data))
    assert main(["clg", "info", str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["similar_copies"] is False and info["conical_shell"] is None
