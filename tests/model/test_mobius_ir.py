"""Möbius lattices (thesis §11.3–11.4) in ``ple-lattice/1``: the optional ``"mobius"`` field holds
each normalized matrix and the split its powers use, so write → read evaluates to the same bits;
plain steady files are unchanged; bad data is refused naming its path."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from ple import Lattice, Pt
from ple.algebra.mobius import Mobius
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.ir import lattice_from_ir, lattice_to_ir
from ple.io.irfile import load_ir, save_ir
from ple.model.mobius import TMIMap, mobius_lattice
from ple.program.sources import load_lattice

PRESETS = Path(__file__).parents[2] / "presets"


def _cell(radius=0.1) -> Lattice:
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), radius)
    b = cell.add_node(Pt(0.4, 0.3, 0.1), radius * 0.7, "b")
    cell.add_beam(a, a, 1, 0, 0)
    cell.add_beam(a, b, 0, 1, 0)
    cell.add_beam(b, a, 0, 0, 1)
    return cell


def _random_mobius(rng, near=0.3) -> Mobius:
    a, b, c, d = 1 + near * (rng.normal(size=4) + 1j * rng.normal(size=4))
    return Mobius.from_coefficients(a, b, c * 0.1, d)


def _lattices():
    rng = np.random.default_rng(5)
    yield "tmi_slab", load_lattice(str(PRESETS / "tmi_slab.py"), {"nu": 5, "nv": 4})
    yield "mobius_slab", load_lattice(str(PRESETS / "mobius_slab.py"), {"nu": 6, "nv": 3})
    u, v, w, g = (_random_mobius(rng) for _ in range(4))
    yield "random 3-pattern", mobius_lattice(_cell(), u, v ** 0.5, w, (4, 3, 3), g)
    yield "TMI, fractional powers", TMIMap.from_five(0, 4, 0.5 + 4j, 4.5 + 5j, 2.2 - 0.6j).lattice(_cell(0.2), (3, 7))


def _same_evaluation(a: Lattice, b: Lattice) -> None:
    ea, eb = a.evaluate().arrays(), b.evaluate().arrays()
    assert ea.keys() == eb.keys()
    for key in ea:
        assert ea[key].dtype == eb[key].dtype and np.array_equal(ea[key], eb[key]), key  # bit for bit


@pytest.mark.parametrize("name,lat", list(_lattices()), ids=lambda x: x if isinstance(x, str) else "")
@pytest.mark.parametrize("resolved", [True, False])
def test_round_trip_is_bit_exact(name, lat, resolved):
    data = lattice_to_ir(lat, resolved)
    assert "mobius" in data and not {"U", "V", "W", "placement"} & set(data)
    back = lattice_from_ir(json.loads(json.dumps(data)))
    assert back.counts == lat.counts and len(back.nodes) == len(lat.nodes)
    assert [(x.n1, x.n2, x.offset) for x in back.beams] == [(x.n1, x.n2, x.offset) for x in lat.beams]
    assert [(x.name, x.radius, tuple(x.center)) for x in back.nodes] == \
        [(x.name, x.radius, tuple(x.center)) for x in lat.nodes]
    _same_evaluation(lat, back)
    assert lattice_to_ir(back, resolved) == data  # and written again, the same data


def test_file_and_cli_round_trip(tmp_path, capsys):
    src = str(PRESETS / "tmi_slab.py")
    lat = load_lattice(src, {"nu": 4, "nv": 3})
    ir = tmp_path / "tmi.json"
    assert main(["ir", src, "--param", "nu=4", "--param", "nv=3", "--out", str(ir)]) == 0
    _same_evaluation(lat, load_ir(ir))
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["eval", src, "--param", "nu=4", "--param", "nv=3", "--out", str(a)]) == 0
    assert main(["eval", str(ir), "--out", str(b)]) == 0
    with np.load(a) as za, np.load(b) as zb:
        for key in za.files:
            assert np.array_equal(za[key], zb[key]), key
    save_ir(load_ir(ir), tmp_path / "again.json")
    assert json.loads((tmp_path / "again.json").read_text()) == json.loads(ir.read_text())
    capsys.readouterr()
    assert main(["info", str(ir), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["group_map"]["kind"] == "Möbius"


def test_a_plain_steady_file_is_unchanged():
    lat = load_lattice(str(PRESETS / "fig6_3.py"), {})
    data = lattice_to_ir(lat)
    assert "mobius" not in data and {"U", "V", "W", "placement"} <= set(data)


def test_missing_directions_are_identities_and_a_matrix_is_normalized():
    m = [[[2.0, 0.0], [0.2, 0.0]], [[0.02, 0.0], [2.0, 0.0]]]  # det 3.996: divided by its root
    data = {"format": "ple-lattice/1", "nodes": [{"center": [0, 0, 0], "radius": 0.1}],
            "beams": [{"from": 0, "to": 0, "offset": [1, 0, 0]}], "mobius": {"U": {"count": 3, "matrix": m}}}
    lat = lattice_from_ir(data)
    assert lat.counts == (3, 1, 1)
    expect = Mobius.from_coefficients(2, 0.2, 0.02, 2)
    assert lat.group_map.u.allclose(expect, 1e-15) and lat.group_map.v.allclose(Mobius.identity(), 0)
    c, r = lat.node_balls([[2, 0, 0, 0]])
    c2, r2 = (expect @ expect).map_balls([[0, 0, 0]], [0.1])
    assert np.allclose(c, c2, atol=1e-14) and np.allclose(r, r2, atol=1e-14)


def _base():
    lat = load_lattice(str(PRESETS / "tmi_slab.py"), {"nu": 2, "nv": 2})
    return lattice_to_ir(lat)


@pytest.mark.parametrize("edit,message", [
    (lambda d: d.update(U={"count": 2, "matrix": [[1, 0, 0, 0]] * 4}), "U: a Möbius lattice places"),
    (lambda d: d.update(placement={"matrix": np.eye(4).tolist()}), "placement: a Möbius lattice"),
    (lambda d: d["mobius"].update(X={}), "mobius.X: unknown field"),
    (lambda d: d["mobius"]["U"].update(matrix=[[[1, 0], [2, 0]], [[1, 0], [2, 0]]]), "mobius.U.matrix: ad - bc = 0"),
    (lambda d: d["mobius"]["U"].update(matrix=[[[1, 0], [0, 0]], [[0, 0]]]), r"mobius.U.matrix\[1\]: expected 2"),
    (lambda d: d["mobius"]["V"].update(count=0), "mobius.V.count: must be at least 1"),
    (lambda d: d["mobius"]["U"]["split"]["similarity"].update(angle=1.0), "mobius.U.split: R ∘ S ∘ R is not"),
    (lambda d: d["mobius"]["U"]["split"]["similarity"].update(axis=[0, 0, 2]), "axis: must be a unit vector"),
    (lambda d: d["mobius"]["U"]["split"]["similarity"].update(factor=-1), "factor: must be positive"),
    (lambda d: d["mobius"]["frame"].update(matrix=[[[float("nan"), 0], [0, 0]], [[0, 0], [1, 0]]]),
     r"mobius.frame.matrix\[0\]\[0\]\[0\]: must be finite"),
])
def test_bad_mobius_data_is_refused_by_path(edit, message):
    data = _base()
    edit(data)
    with pytest.raises(PleError, match=message):
        lattice_from_ir(data)


def test_other_group_maps_still_have_no_ir_form():
    from ple.model.groupmap import GroupMap

    class Shift(GroupMap):
        kind = "shift"

        def map_balls(self, i, j, k, centers, radii):
            return centers + np.stack([i, j, k], axis=1), radii

        def describe(self):
            return {"kind": self.kind}

    lat = _cell()
    lat.set_group_map(Shift(), (2, 2, 2))
    with pytest.raises(PleError, match="a lattice placed by a shift map has no ple-lattice/1 form"):
        lattice_to_ir(lat)
