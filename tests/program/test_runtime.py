"""Lattice programs (SPEC §4): inputs from the signature, the API in scope, errors that name the
file and line, inputs from text, presets and sources."""

from __future__ import annotations

import json

import numpy as np
import pytest
from ple import Lattice, PleError, Translation, Vec
from ple.io.irfile import save_ir
from ple.program.presets import preset_description, preset_names, preset_path
from ple.program.runtime import Param, Range, compile_program, parse_param_value, parse_params
from ple.program.sources import load_lattice, resolve_source

PROGRAM = '''"""A row of balls."""
def lattice(n: Range(1, 50) = 4, radius=0.1, closed=False, label="row"):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    lat.add_beam(a, a, 1, 0, 0)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    return lat
'''


def test_inputs_come_from_the_signature():
    prog = compile_program(PROGRAM, "row.py")
    params = {p.name: p for p in prog.parameters()}
    assert list(params) == ["n", "radius", "closed", "label"]
    assert params["n"].range == Range(1, 50) and params["n"].kind is int and params["radius"].kind is float
    assert prog.description == "A row of balls."
    lat = prog.run(n=7, radius=0.2)
    assert isinstance(lat, Lattice) and lat.counts == (7, 1, 1)
    assert np.allclose(lat.evaluate().center[:, 0], np.arange(7)) and np.allclose(lat.evaluate().radius, 0.2)


def test_program_errors_name_file_and_line():
    with pytest.raises(PleError, match=r"bad.py:3: program raised ZeroDivisionError"):
        compile_program("def lattice():\n    x = 1\n    return 1 / 0\n", "bad.py").run()
    with pytest.raises(PleError, match=r"bad.py:2: syntax error"):
        compile_program("def lattice():\n    return (\n", "bad.py")
    with pytest.raises(PleError, match="must define a function lattice"):
        compile_program("x = 1\n", "bad.py")
    with pytest.raises(PleError, match="must return a Lattice"):
        compile_program("def lattice():\n    return 3\n", "bad.py").run()
    with pytest.raises(PleError, match="needs a default"):
        compile_program("def lattice(n):\n    return Lattice()\n", "bad.py").parameters()
    with pytest.raises(PleError, match="unknown parameter 'm'"):
        compile_program(PROGRAM, "row.py").run(m=3)


def test_input_text_is_converted_to_the_default_type():
    assert parse_param_value(Param("n", 3), "12") == 12
    assert parse_param_value(Param("r", 0.1), "2.5e-1") == 0.25
    assert parse_param_value(Param("b", False), "yes") is True
    assert parse_param_value(Param("s", "a"), "word") == "word"
    for param, bad in ((Param("n", 3), "1.5"), (Param("r", 0.1), "nan"), (Param("b", False), "maybe")):
        with pytest.raises(PleError, match=param.name):
            parse_param_value(param, bad)
    prog = compile_program(PROGRAM, "row.py")
    assert parse_params(prog, ["n=9", "closed=true"]) == {"n": 9, "closed": True}
    with pytest.raises(PleError, match="unknown parameter"):
        parse_params(prog, ["size=3"])


def test_programs_may_import_ple():
    lat = compile_program("from ple import Lattice as L\nimport ple\ndef lattice():\n"
                          "    lat = L()\n    lat.add_node(ple.Pt(1, 2, 3), 0.5)\n    return lat\n").run()
    assert np.allclose(lat.evaluate().center, [[1, 2, 3]])


def test_presets_and_sources(tmp_path):
    names = preset_names()
    assert "fig6_3" in names and "cubic" in names and all(not n.startswith("_") for n in names)
    assert preset_path("fig6_3").suffix == ".py" and preset_path("no_such_preset") is None
    assert preset_description("fig6_3")
    with pytest.raises(PleError, match="presets: "):
        resolve_source("no_such_preset")
    with pytest.raises(PleError, match="no such file"):
        resolve_source(str(tmp_path / "missing.py"))
    prog = tmp_path / "row.py"
    prog.write_text(PROGRAM)
    assert load_lattice(str(prog), ["n=3"]).counts == (3, 1, 1)
    assert load_lattice(str(prog), {"n": 5}).counts == (5, 1, 1)
    ir = tmp_path / "row.json"
    save_ir(load_lattice(str(prog), ["n=6"]), ir)
    assert json.loads(ir.read_text())["format"] == "ple-lattice/1"
    back = load_lattice(str(ir))
    assert back.counts == (6, 1, 1) and np.allclose(back.U.matrix, Translation(Vec(1, 0, 0)).matrix)
    with pytest.raises(PleError, match="has no parameters"):
        load_lattice(str(ir), ["n=2"])
