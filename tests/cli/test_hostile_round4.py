"""The fourth round of hostile inputs (docs/reliability.md): numbers beyond float64, noise in
messages, programs whose process trees outlive them, and bodies of extreme sizes. Each case runs
``ple`` in a subprocess (its real stderr and exit code, numpy's warnings included) and must end
with exit 0 and a right result, or exit 2 and one line naming the problem."""

from __future__ import annotations

import json

import numpy as np
import pytest
from ple.errors import PleError
from ple.model.budget import PRECISION, TINY, check_lattice
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice
from reliability_helpers import assert_clean_failure, ple


def _ir(radius: float = 0.1, beams=None, **directions) -> dict:
    ir = {"format": "ple-lattice/1",
          "nodes": [{"id": "a", "center": [0, 0, 0], "radius": radius},
                    {"id": "b", "center": [0.5, 0, 0], "radius": radius}],
          "beams": beams if beams is not None else [{"from": "a", "to": "b", "offset": [0, 0, 0]},
                                                   {"from": "a", "to": "a", "offset": [1, 0, 0]}]}
    ir.update(directions)
    return ir


def _dir(count: int, kind: str, **p) -> dict:
    return {"count": count, "similarity": {"kind": kind, **p}}


def _scaling(count: int, factor: float) -> dict:
    return _dir(count, "scaling", factor=factor, point=[0, 0, 0])


def _no_noise(run) -> None:
    assert "Warning" not in run.stderr and "Traceback" not in run.stderr, run.stderr


# ----- numbers beyond float64: one named error ---------------------------------------------------------
NUMBERS = [
    ("scaling 2, count 100", _ir(U=_scaling(100, 2)), ("loses all precision", "U (a scaling, factor 2, count 100)")),
    ("translation 1e99", _ir(U=_dir(3, "translation", vector=[1e99, 0, 0])),
     ("loses all precision", "U (a translation, count 3)")),
    ("translation 4e99 along W", _ir(W=_dir(3, "translation", vector=[0, 0, 4e99])), ("loses all precision", "W (")),
    ("scaling 0.5, count 2000", _ir(V=_scaling(2000, 0.5)),
     ("underflows to zero scale", "V (a scaling, factor 0.5, count 2000)")),
    ("scaling 1000, count 200", _ir(U=_scaling(200, 1e3)), ("overflows", "U (a scaling, factor 1000, count 200)")),
    ("radius 5e-324", _ir(radius=5e-324, U=_dir(3, "translation", vector=[1, 0, 0])),
     ("underflows to zero scale", "radii down to 4.94e-324", "smallest meaningful size")),
    ("radius 1e-90 beside a cell of 1", _ir(radius=1e-90, U=_dir(3, "translation", vector=[1, 0, 0])),
     ("loses all precision", "radius 1e-90")),
]


@pytest.mark.parametrize("command", ["info", "check"])
@pytest.mark.parametrize("name, data, needles", NUMBERS, ids=[n[0] for n in NUMBERS])
def test_numbers_beyond_float64_are_one_named_error(tmp_path, command, name, data, needles):
    path = tmp_path / "l.json"
    path.write_text(json.dumps(data))
    run = ple(command, path)
    assert_clean_failure(run, *needles)
    _no_noise(run)


def test_a_program_overflowing_is_named_like_an_ir_file(tmp_path):
    prog = tmp_path / "p.py"
    prog.write_text("from ple.model.lattice import Lattice\nfrom ple.algebra.similarity import Scaling\n"
                    "def lattice():\n    lat = Lattice()\n    a = lat.add_node([0.5, 0, 0], 0.1)\n"
                    "    lat.add_beam(a, a, 1, 0, 0)\n    lat.set_u(100, Scaling(2, [0, 0, 0]))\n    return lat\n")
    run = ple("info", prog)
    assert_clean_failure(run, "p.py", "loses all precision", "U (a scaling, factor 2, count 100)")


@pytest.mark.parametrize("param, needle", [("radius=5e-324", "underflows to zero scale"),
                                           ("radius=1e-300", "underflows to zero scale"),
                                           ("cell=1e300", "overflows")])
def test_preset_parameters_beyond_float64_are_named(param, needle):
    run = ple("info", "cubic", "--param", param)
    assert_clean_failure(run, needle)
    _no_noise(run)


def test_a_wide_but_representable_range_is_answered_not_crashed(tmp_path):
    """Scaling 2, count 45: radii from 0.1 to 1.8·10¹², every ball placed to float64's precision,
    is accepted; info answers its counts (its quick clean look is skipped: one grid cannot hold
    sizes that far apart) and check refuses with the sizes, instead of a traceback."""
    path = tmp_path / "l.json"
    path.write_text(json.dumps(_ir(U=_scaling(45, 2))))
    run = ple("info", path)
    assert run.returncode == 0, run.stderr
    _no_noise(run)
    assert "45 x 1 x 1" in run.stdout
    assert_clean_failure(ple("check", path), "too far apart for one grid")


def test_the_limits_are_exact_at_their_edges():
    """Independent of the CLI: a radius just above TINY passes, below it is refused; a ball of radius
    r at coordinate x passes while r >= PRECISION · x."""
    def lat(radius, x):
        out = Lattice()
        out.add_node([x, 0, 0], radius)
        return out
    check_lattice(lat(2 * TINY, 0.0))
    with pytest.raises(PleError, match="underflows to zero scale"):
        check_lattice(lat(TINY / 2, 0.0))
    check_lattice(lat(1.0, 0.5 / PRECISION))
    with pytest.raises(PleError, match="loses all precision"):
        check_lattice(lat(1.0, 2 / PRECISION))


# ----- duplicated beam-patterns: refused, not measured twice -------------------------------------------
@pytest.mark.parametrize("second", [{"from": "a", "to": "b", "offset": [0, 0, 0]},
                                    {"from": "b", "to": "a", "offset": [0, 0, 0]},
                                    {"from": "a", "to": "a", "offset": [-1, 0, 0]}])
def test_a_beam_pattern_given_twice_is_refused(tmp_path, second):
    beams = [{"from": "a", "to": "b", "offset": [0, 0, 0]}, {"from": "a", "to": "a", "offset": [1, 0, 0]}]
    path = tmp_path / "l.json"
    path.write_text(json.dumps(_ir(beams=beams + [second] * 49, U=_dir(3, "translation", vector=[1, 0, 0]))))
    run = ple("info", path)
    assert_clean_failure(run, "beams[2]", "repeats beams[")
    _no_noise(run)


def test_distinct_beam_patterns_are_kept():
    lat = load_lattice("cubic")
    check_lattice(lat)
    assert len({(b.n1, b.n2, b.offset) for b in lat.beams}) == len(lat.beams)


# ----- biq with a huge query ----------------------------------------------------------------------------
@pytest.mark.parametrize("row", [[0, 0, 0, 1e300], [1e200, 0, 0, 1]])
def test_a_huge_query_ball_is_refused_without_warnings(tmp_path, row):
    q = tmp_path / "q.npy"
    np.save(q, np.array([row], float))
    run = ple("biq", "cubic", "--queries", q, "--out", tmp_path / "h.json")
    assert_clean_failure(run, "--queries", "beyond 1e+100")
    _no_noise(run)
    assert not (tmp_path / "h.json").exists()


def test_a_query_of_every_element_is_answered(tmp_path):
    q = tmp_path / "q.npy"
    np.save(q, np.array([[0, 0, 0, 1e100]], float))
    run = ple("biq", "cubic", "--queries", q, "--out", tmp_path / "h.json", "--count")
    assert run.returncode == 0, run.stderr
    _no_noise(run)
    lat = load_lattice("cubic")
    counts = json.loads((tmp_path / "h.json").read_text())["queries"][0]
    assert counts == {"nodes": lat.node_count(), "beams": lat.beam_count()}


# ----- messages bounded: an echoed key or value is cut to 80 characters ----------------------------------
def test_cut_keeps_short_text_and_cuts_long_text_to_the_limit():
    from ple.errors import ECHO_LIMIT, cut, echo
    assert cut("offset") == "offset"
    assert cut("x" * ECHO_LIMIT) == "x" * ECHO_LIMIT
    long = cut("x" * (ECHO_LIMIT + 1))
    assert len(long) == ECHO_LIMIT and long.endswith("…") and long.startswith("x" * (ECHO_LIMIT - 1))
    assert echo("ab") == "'ab'" and len(echo("y" * 10**6)) == ECHO_LIMIT


def _bounded(run, needle: str) -> None:
    """Exit 2, one error line (after argparse's usage, for its errors) quoting ``needle``, short."""
    if "usage:" in run.stderr:
        assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
        last = run.stderr.strip().splitlines()[-1]
        assert last.startswith("ple ") and needle in last, run.stderr
    else:
        assert_clean_failure(run, needle)
    assert len(run.stderr) < 2000, len(run.stderr)


KEY = "k" * 1_000_000


@pytest.mark.parametrize("where", ["top", "node", "similarity", "filter"])
def test_a_key_of_a_million_characters_is_cut(tmp_path, where):
    data = _ir(U=_dir(3, "translation", vector=[1, 0, 0]))
    {"top": data, "node": data["nodes"][0], "similarity": data["U"]["similarity"]}.get(where, {})[KEY] = 1
    if where == "filter":
        data["filter"] = {"cleanup": {KEY: 1}}
    path = tmp_path / "l.json"
    path.write_text(json.dumps(data))
    _bounded(ple("info", path), "k" * 79 + "…")


def test_a_clg_key_of_a_million_characters_is_cut(tmp_path):
    from pathlib import Path
    plate = json.loads((Path(__file__).resolve().parents[2] / "presets" / "clg" / "plate.json").read_text())
    plate[KEY] = 1
    path = tmp_path / "c.json"
    path.write_text(json.dumps(plate))
    _bounded(ple("clg", "info", path), "k" * 79 + "…")


VALUE = "v" * 100_000  # an argument of the command line (at most 128 KiB each on Linux)


@pytest.mark.parametrize("args", [("info", VALUE), ("info", "cubic", "--param", f"n={VALUE}"),
                                  ("info", "cubic", "--param", f"{VALUE}=1"),
                                  ("mesh", "cubic", "--style", VALUE, "--out", "m.stl"),
                                  ("mesh", "cubic", "--unit", VALUE, "--out", "m.stl")],
                         ids=["preset", "param value", "param name", "style", "unit"])
def test_a_long_argument_is_cut(tmp_path, args):
    _bounded(ple(*args, cwd=tmp_path), "v" * 78 + "…")


# ----- bodies of extreme sizes and inside-out bodies: one reader -------------------------------------------
def _box(path, side: float, inverted: bool = False) -> str:
    import trimesh
    box = trimesh.creation.box((side, side, side))
    if inverted:
        box.invert()
    box.export(path)
    return str(path)


def _fit(tmp_path, mesh: str, *flags) -> tuple[int, dict | None, str]:
    run = ple("fit", mesh, "--orders", "8", *flags, "--out", tmp_path / "f.npz")
    _no_noise(run)
    return run.returncode, json.loads(run.stdout.split("\nnote:")[0]) if run.returncode == 0 else None, run.stderr


@pytest.mark.parametrize("side", [1e30, 1e-30, 4e10])
def test_fit_reads_a_closed_box_at_any_scale_as_a_box_of_side_1(tmp_path, side):
    """--normalize maps every box to the same cell: the fit of a box of side 1e30 or 1e-30 is the
    fit of a box of side 1 (the reader merges with a tolerance relative to the box)."""
    code, unit, err = _fit(tmp_path, _box(tmp_path / "unit.stl", 1.0), "--normalize")
    assert code == 0, err
    code, rep, err = _fit(tmp_path, _box(tmp_path / "box.stl", side), "--normalize")
    assert code == 0, err
    assert rep["order"] == unit["order"] and rep["hausdorff"] == pytest.approx(unit["hausdorff"], rel=1e-6)
    assert rep["scale"] == pytest.approx(0.9 / side, rel=1e-6)


@pytest.mark.parametrize("flags", [(), ("--normalize",), ("--distance",), ("--normalize", "--distance"),
                                   ("--normalize", "--no-symmetric")])
def test_an_inverted_mesh_is_named_so_for_every_flag(tmp_path, flags):
    code, _, err = _fit(tmp_path, _box(tmp_path / "inv.stl", 0.8, inverted=True), *flags)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "inverted (inside out" in err and "--flip" in err
    assert not (tmp_path / "f.npz").exists()


def test_flip_fits_an_inverted_mesh_as_the_right_one(tmp_path):
    code, right, err = _fit(tmp_path, _box(tmp_path / "box.stl", 0.8), "--normalize")
    assert code == 0, err
    code, flipped, err = _fit(tmp_path, _box(tmp_path / "inv.stl", 0.8, inverted=True), "--normalize", "--flip")
    assert code == 0, err
    assert flipped["hausdorff"] == pytest.approx(right["hausdorff"], rel=1e-9) and flipped["met"] == right["met"]


def test_a_body_fill_reads_an_inverted_box_as_the_box(tmp_path):
    right = ple("info", "cubic", "--param", "n=4", "--body", _box(tmp_path / "box.stl", 2.5))
    inverted = ple("info", "cubic", "--param", "n=4", "--body", _box(tmp_path / "inv.stl", 2.5, inverted=True))
    assert right.returncode == 0 and inverted.returncode == 0, (right.stderr, inverted.stderr)
    _no_noise(inverted)
    assert "8 of 64" in right.stdout  # the balls at 0 and 1 on each axis lie inside [-1.25, 1.25]³
    assert right.stdout == inverted.stdout.replace("inv.stl", "box.stl")
