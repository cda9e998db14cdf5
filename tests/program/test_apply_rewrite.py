"""Apply to Program (snippets.apply_edits) on programs the first version refused or cluttered:
``return <expression>`` endings (every becots_* preset), edits of calls inside branches
(the warped preset) rewritten in place, and repeated applies that add no lines."""

from __future__ import annotations

import numpy as np
import pytest
from ple.algebra.similarity import Rotation, Translation
from ple.algebra.vectors import Pt, Vec
from ple.errors import PleError
from ple.program.presets import preset_names, preset_path
from ple.program.runtime import compile_program
from ple.program.snippets import SetBecots, SetDirection, apply_edits, apply_to_lattice, lattices_close
from ple.program.sources import load_lattice

BECOTS = [n for n in preset_names() if n.startswith("becots_")]


def moved_corners(lat):
    data = lat.becots.to_ir()
    if set(data) != {"corners", "counts"}:
        return None
    corners = [tuple(c) for c in data["corners"]]
    corners[2] = tuple(np.add(corners[2], [0.5, -0.25, 0.4]))
    return SetBecots(tuple(corners), tuple(lat.becots.counts))


@pytest.mark.parametrize("name", BECOTS)
def test_becots_presets_apply(name):
    source = preset_path(name).read_text()
    lat = load_lattice(name)
    edit = moved_corners(lat)
    if edit is None:
        pytest.skip(f"{name}: a stacked or closed slab has no corners to drag")
    new = apply_edits(source, [edit], name=name)
    again = compile_program(new).run()
    assert lattices_close(again, apply_to_lattice(lat, [edit]), 1e-9)
    assert new.count("set_becots(") == 1 and new.rstrip().endswith("return lat")
    # applying again rewrites that call in place: no new lines
    edit2 = SetBecots(tuple(tuple(np.add(c, 0.1)) for c in edit.corners), edit.counts)
    newer = apply_edits(new, [edit2], name=name)
    assert newer.count("\n") == new.count("\n") and newer.count("set_becots(") == 1
    assert lattices_close(compile_program(newer).run(), apply_to_lattice(lat, [edit2]), 1e-9)


def test_return_expression_gets_a_fresh_name_when_lat_is_taken():
    source = ("def lattice(lat: Range(1, 5) = 3):\n"
              "    base = Lattice()\n"
              "    a = base.add_node(Pt(0, 0, 0), 0.1)\n"
              "    base.add_beam(a, a, 1, 0, 0)\n"
              "    base.set_u(int(lat), Translation(Vec(1, 0, 0)))\n"
              "    return base.copy()\n")
    edit = SetDirection("u", 4, Translation(Vec(2, 0, 0)))
    new = apply_edits(source, [edit], {"lat": 3})
    assert "lattice_ = base.copy()" in new and "return lattice_" in new
    got = compile_program(new).run(lat=3)
    assert got.u.count == 4 and np.allclose(got.U.matrix[:3, 3], [2, 0, 0])


WARPED_BRANCH = "lat.set_u(n, Rotation(bend, Vec(0, -1, 0), Pt(0, 0, span / bend)), cumulative=True)"
WARPED_ELSE = "lat.set_u(n, Translation(Vec(span, 0, 0)), cumulative=True)"


@pytest.mark.parametrize("bend", [1.2, 0.0])
def test_branch_that_ran_is_rewritten_in_place(bend):
    source = preset_path("warped").read_text()
    assert WARPED_BRANCH in source and WARPED_ELSE in source
    params = {"bend": bend}
    lat = compile_program(source).run(**params)
    text = source
    for step in range(3):
        sim = Rotation(0.05 * (step + 1), Vec(0, 1, 0), Pt(0, 0, 7.5))
        edit = SetDirection("u", None, sim, True)
        want = apply_to_lattice(lat, [edit])
        text = apply_edits(text, [edit], params)
        assert text.count("\n") == source.count("\n") and text.count("lat.set_u(") == 2
        assert lattices_close(compile_program(text).run(**params), want, 1e-9)
    kept = WARPED_ELSE if bend > 0 else WARPED_BRANCH  # the branch that did not run is untouched
    assert kept in text and (WARPED_BRANCH if bend > 0 else WARPED_ELSE) not in text


def test_call_in_a_loop_is_rewritten_in_place():
    source = ("def lattice():\n"
              "    lat = Lattice()\n"
              "    a = lat.add_node(Pt(0, 0, 0), 0.1)\n"
              "    lat.add_beam(a, a, 1, 0, 0)\n"
              "    for k in range(2):\n"
              "        lat.set_u(3, Translation(Vec(1 + k, 0, 0)))\n"
              "    return lat\n")
    edit = SetDirection("u", 5, Translation(Vec(0.5, 0, 0)))
    new = apply_edits(source, [edit])
    assert new.count("\n") == source.count("\n")  # both loop runs are the same call: rewritten in place
    got = compile_program(new).run()
    assert got.u.count == 5 and np.allclose(got.U.matrix[:3, 3], [0.5, 0, 0])


def test_broken_program_still_reports():
    with pytest.raises(PleError, match="syntax error"):
        apply_edits("def lattice(:\n", [SetDirection("u", 2)])
