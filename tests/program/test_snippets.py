"""GUI edits as program code: snippets, program rewriting, round trips (core/ple/snippets.py)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple import PleError, Pt, Rotation, Scaling, Screw, Swirl, Translation, Vec
from ple.program.presets import preset_names, preset_path
from ple.program.runtime import compile_program
from ple.program.snippets import (
    AddBeam,
    AddNode,
    MoveNode,
    RemoveBeam,
    RemoveNode,
    SetBecots,
    SetDirection,
    SetPlacement,
    apply_edits,
    apply_to_lattice,
    coalesce,
    edits_from_json,
    edits_to_json,
    lattices_close,
    snippet,
)

FIG6_1 = '''"""Thesis Fig. 6.1: the template program."""


def lattice(thickness=0.1):
    lat = Lattice()
    # the template node-group
    a = lat.add_node(Pt(0, 0, 0), thickness)
    lat.add_beam(a, a, 1, 0, 0)  # beam-patterns
    lat.add_beam(a, a, 0, 1, 0)
    lat.add_beam(a, a, 0, 0, 1)
    lat.set_u(3, Translation(Vec(1, 0, 0)))
    lat.set_v(3, Translation(Vec(0, 1, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 1)))  # repetition counts 3
    return lat
'''

FIG6_3_EDITS = [
    SetDirection("u", 7, Scaling(1.187, Pt(-3.333, 0, 0))),
    SetDirection("v", 12, Rotation(0.285, Vec(0, 0, 1), Pt(-1.555, 0.003, 0))),
    SetDirection("w", 15, Swirl(0.224, Vec(0, 1, 0), Pt(10.872, 0, 0.039), 0.953)),
    AddBeam(0, 0, 1, 1, 0),
]


def _run(src, **params):
    return compile_program(src).run(**params)


def test_fig6_3_snippet_reads_like_the_thesis():
    text = snippet(FIG6_3_EDITS, digits=3)
    assert text.splitlines() == [
        "lat.set_u(7, Scaling(1.187, Pt(-3.333, 0, 0)))",
        "lat.set_v(12, Rotation(0.285, Vec(0, 0, 1), Pt(-1.555, 0.003, 0)))",
        "lat.set_w(15, Swirl(0.224, Vec(0, 1, 0), Pt(10.872, 0, 0.039), 0.953))",
        "lat.add_beam(0, 0, 1, 1, 0)",
    ]


def test_apply_rewrites_in_place_and_keeps_comments():
    new = apply_edits(FIG6_1, FIG6_3_EDITS)
    assert "# the template node-group" in new and "# beam-patterns" in new and "# repetition counts 3" in new
    assert new.count(".set_u(") == 1 and new.count(".set_w(") == 1
    assert "lat.set_u(7, Scaling(1.187, Pt(-3.333, 0, 0)))" in new
    assert new.splitlines()[:9] == FIG6_1.splitlines()[:9]  # unrelated code untouched
    got = _run(new)
    assert lattices_close(got, apply_to_lattice(_run(FIG6_1), FIG6_3_EDITS))
    assert got.counts == (7, 12, 15) and len(got.beams) == 4


def test_count_only_edit_keeps_the_similarity_expression():
    new = apply_edits(FIG6_1, [SetDirection("v", 5)])
    assert "lat.set_v(5, Translation(Vec(0, 1, 0)))" in new
    src = FIG6_1.replace("def lattice(thickness=0.1):", "def lattice(thickness=0.1, n=3):").replace(
        "lat.set_u(3,", "lat.set_u(n,")
    new = apply_edits(src, [SetDirection("u", similarity=Translation(Vec(2, 0, 0)))], params={"n": 4})
    assert "lat.set_u(n, Translation(Vec(2, 0, 0)))" in new  # the parameter stays a parameter
    assert _run(new, n=6).counts[0] == 6


def test_move_node_keeps_parameter_radius():
    new = apply_edits(FIG6_1, [MoveNode(0, (0.5, 0.25, 0))])
    assert "a = lat.add_node(Pt(0.5, 0.25, 0), thickness)" in new
    assert _run(new, thickness=0.2).nodes[0].radius == 0.2


def test_fallback_appends_when_in_place_would_change_meaning():
    src = FIG6_1.replace("lat.set_v(3, Translation(Vec(0, 1, 0)))", "lat.set_v(3, lat.U)")
    edits = [SetDirection("u", None, Translation(Vec(2, 0, 0)))]
    new = apply_edits(src, edits)
    assert new.count(".set_u(") == 2  # the original stays; the edit is appended before return
    assert lattices_close(_run(new), apply_to_lattice(_run(src), edits))


def test_loops_and_removals_are_appended():
    src = FIG6_1.replace("    lat.set_w(3, Translation(Vec(0, 0, 1)))  # repetition counts 3\n",
                         "    for name in ['w']:\n        lat.set_w(3, Translation(Vec(0, 0, 1)))\n")
    edits = [SetDirection("w", 4, Screw(0.3, Vec(0, 0, 1), Pt(0, 0, 0), 1.0), cumulative=True),
             AddNode((0.5, 0.5, 0.5), 0.05, "b"), AddBeam(0, 1), RemoveBeam(0), RemoveNode(0),
             SetPlacement(Rotation(0.5, Vec(1, 0, 0), Pt(0, 0, 0)))]
    new = apply_edits(src, edits)
    assert "    lat.remove_node(0)\n    lat.set_placement(" in new
    assert new.rstrip().endswith("return lat")
    assert lattices_close(_run(new), apply_to_lattice(_run(src), edits))


def test_bad_programs_are_reported():
    with pytest.raises(PleError, match="return"):
        apply_edits("def lattice():\n    lat = Lattice()\n    lat.add_node(Pt(0,0,0), 1)\n    if True:\n"
                    "        return lat\n", [SetDirection("u", 2)])
    with pytest.raises(PleError, match="lattice"):
        apply_edits("x = 1\n", [SetDirection("u", 2)])
    with pytest.raises(PleError, match="syntax"):
        apply_edits("def lattice(:\n", [])
    with pytest.raises(PleError, match="node 5"):
        apply_to_lattice(_run(FIG6_1), [MoveNode(5, (0, 0, 0))])


def test_coalesce_and_json_round_trip():
    edits = [SetDirection("u", 4), SetDirection("u", None, Translation(Vec(2, 0, 0))), MoveNode(0, (1, 0, 0)),
             MoveNode(0, None, 0.3), SetPlacement(Scaling(2, Pt(0, 0, 0))), SetPlacement(Scaling(3, Pt(0, 0, 0)))]
    short = coalesce(edits)
    assert len(short) == 3
    assert short[0] == SetDirection("u", 4, Translation(Vec(2, 0, 0)))
    assert short[1] == MoveNode(0, (1, 0, 0), 0.3)
    base = _run(FIG6_1)
    assert lattices_close(apply_to_lattice(base, short), apply_to_lattice(base, edits))
    back = edits_from_json(edits_to_json(edits))
    assert lattices_close(apply_to_lattice(base, back), apply_to_lattice(base, edits))
    with pytest.raises(PleError):
        edits_from_json('[{"type": "Explode"}]')


sims = st.sampled_from([
    Translation(Vec(1.1, 0.2, 0)), Rotation(0.71, Vec(0, 0, 1), Pt(1, 0, 0)), Scaling(1.13, Pt(0, -1, 2)),
    Swirl(0.4, Vec(1, 2, 3), Pt(2, 0, 1), 0.87), Screw(2.5, Vec(0, 1, 0), Pt(0, 0, 3), 0.4)])
edit_st = st.one_of(
    st.builds(SetDirection, st.sampled_from("uvw"), st.integers(1, 5), sims, st.booleans()),
    st.builds(SetDirection, st.sampled_from("uvw"), st.integers(1, 5)),
    st.builds(SetPlacement, sims),
    st.builds(MoveNode, st.just(0), st.tuples(*[st.floats(-2, 2)] * 3), st.floats(0.01, 0.3)),
    st.builds(AddNode, st.tuples(*[st.floats(-2, 2)] * 3), st.floats(0.01, 0.3)),
    st.builds(AddBeam, st.just(0), st.just(0), st.integers(-1, 1), st.integers(-1, 1), st.just(1)),
)


@settings(max_examples=25, deadline=None)
@given(st.sampled_from(sorted(n for n in preset_names() if preset_path(n).suffix == ".py" and n != "warped")),
       st.lists(edit_st, min_size=1, max_size=6))  # programs only: a .json preset is data
def test_round_trip_apply_rerun_same_lattice(preset, edits):
    src = preset_path(preset).read_text()
    base = _run(src)
    if base.becots is not None:
        return
    want = apply_to_lattice(base, edits)
    got = _run(apply_edits(src, edits))
    assert lattices_close(got, want, 1e-9)
    # and the evaluated balls agree (independent of how the lattice was built)
    r = "0:1,0:1,0:1"
    assert np.allclose(got.evaluate(r).center, want.evaluate(r).center, atol=1e-9)


def test_becots_corner_edit_round_trip():
    src = '''def lattice(nu=4):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.05)
    lat.add_beam(a, a, 1, 0, 0)
    lat.add_beam(a, a, 0, 1, 0)
    # the slab's corners
    lat.set_becots(Pt(0, 0, 0), Pt(0, 4, 0), Pt(4.5, 5, 0), Pt(4, 0, 0), counts=(nu, 4))
    return lat
'''
    edit = SetBecots(((0, 0, 0), (-0.5, 4, 0), (4.5, 6, 0), (5, 0.5, 0)), (4, 4))
    new = apply_edits(src, [edit])
    assert new.count("set_becots(") == 1 and "# the slab's corners" in new
    assert lattices_close(_run(new), apply_to_lattice(_run(src), [edit]))
    assert edits_from_json(edits_to_json([edit])) == [edit]
