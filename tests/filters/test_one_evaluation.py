"""One evaluation is the truth (issue 12): a filtered lattice is one object that every door
treats the same way — eval, info, BIQ/PMC/distance, the beam-lattice 3MF, IR files — checked
against brute force over the kept elements; filters round-trip through ``ple-lattice/1``."""

from __future__ import annotations

import json
import re
import zipfile

import numpy as np
import pytest
from lattices import centre_on, random_lattice
from ple import Lattice, Pt, Translation, Vec
from ple.algebra.elements import ball_ball_interfere, ball_beam_interfere, beam_distance
from ple.cli.info import lattice_info
from ple.cli.main import main
from ple.filters import LiL, Stencil, lil
from ple.filters.implicit import FourierField, ImplicitFilter, TPMSField
from ple.filters.ir import filter_from_dict, lattice_from_ir, lattice_to_ir
from ple.io.irfile import load_ir, save_ir
from ple.queries import biq


def _sets(ev):
    return {tuple(x) for x in ev.node_index}, {tuple(x) for x in ev.beam_index}


def filtered_cases():
    """Filtered lattices of every kind: stencil (per group and per node id), LiL, a cascade,
    an implicit field, a Fourier field and compounds."""
    rng = np.random.default_rng(7)
    fine = random_lattice(rng, ["translation", "rotation", "screw"], (6, 5, 4), step=1.0, radius=0.12)
    medium = random_lattice(rng, ["scaling", "translation", "translation"], (3, 3, 2), step=1.8, radius=0.3, nodes=1)
    coarse = random_lattice(rng, ["translation", "translation", "translation"], (2, 2, 2), step=2.5, radius=0.5,
                            nodes=1)
    centre_on(medium, fine)
    centre_on(coarse, fine)
    gyroid = ImplicitFilter(TPMSField("gyroid", 2.5), 0.3, "sheet")
    fourier = ImplicitFilter(FourierField([[1, 0, 0], [0, 1, 1]], [0.5 + 0.1j, -0.25], 4, 3.0,
                                          Translation(Vec(0.2, 0, 0))), 0.1)
    cases = {
        "stencil": fine.with_filter(Stencil.named("edges", 2)),
        "stencil_nodes": fine.with_filter(Stencil(np.array([[[[True, False]]], [[[False, True]]]]))),
        "lil": lil(fine, medium),
        "cascade": lil(fine, medium, coarse),
        "implicit": fine.with_filter(gyroid),
        "fourier_not": fine.with_filter(~fourier),
        "or_and": fine.with_filter((Stencil.named("checker", 2) | gyroid) & LiL(medium)),
    }
    return cases


CASES = filtered_cases()


@pytest.mark.parametrize("name", sorted(CASES))
def test_filtered_lattice_round_trips_through_the_ir(name, tmp_path):
    lat = CASES[name]
    save_ir(lat, tmp_path / "f.json")
    data = json.loads((tmp_path / "f.json").read_text())
    assert "filter" in data
    back = load_ir(tmp_path / "f.json")
    assert _sets(back.evaluate()) == _sets(lat.evaluate())
    assert 0 < len(lat.evaluate().node_index) < lat.node_count()  # the filter really removes nodes
    # the canonical form too (similarities as kinds, not matrices)
    again = lattice_from_ir(json.loads(json.dumps(lattice_to_ir(lat, resolved=False))))
    assert _sets(again.evaluate()) == _sets(lat.evaluate())


@pytest.mark.parametrize("name", sorted(CASES))
def test_info_counts_equal_the_evaluation(name):
    lat = CASES[name]
    ev = lat.evaluate()
    info = lattice_info(lat)
    assert info["filtered"] and (info["nodes"], info["beams"]) == (len(ev.node_index), len(ev.beam_index))
    lo = (ev.center - ev.radius[:, None]).min(axis=0)
    assert np.allclose(info["bounds"]["min"], lo)
    region = "1:4,0:3,2:4"
    sub = lat.evaluate(region)
    info = lattice_info(lat, region)
    assert (info["nodes"], info["beams"]) == (len(sub.node_index), len(sub.beam_index))


@pytest.mark.parametrize("name", sorted(CASES))
def test_queries_never_hit_removed_elements(name, rng):
    lat = CASES[name]
    ev = lat.evaluate()
    lo, hi = ev.center.min(axis=0), ev.center.max(axis=0)
    qc = lo + (hi - lo) * rng.random((60, 3))
    qr = rng.random(60) * 0.5
    res = biq.query(lat, qc, qr)
    a, b = ev.beam_nodes[:, 0], ev.beam_nodes[:, 1]
    for q, x in enumerate(res):  # brute force over the kept elements only
        nodes = ball_ball_interfere(ev.center, ev.radius, qc[q], qr[q])
        beams = ball_beam_interfere(qc[q], qr[q], ev.center[a], ev.radius[a], ev.center[b], ev.radius[b])
        assert {tuple(n) for n in x.nodes} == {tuple(n) for n in ev.node_index[nodes]}
        assert {tuple(n) for n in x.beams} == {tuple(n) for n in ev.beam_index[beams]}
    inside = biq.pmc(lat, qc)
    brute = (np.min(np.linalg.norm(ev.center[None] - qc[:, None], axis=2) - ev.radius, axis=1) <= 0)
    if len(ev.beam_nodes):
        d = beam_distance(qc[:, None], ev.center[a], ev.radius[a], ev.center[b], ev.radius[b])
        brute |= d.min(axis=1) <= 0
    assert np.array_equal(inside, brute)
    d = biq.distance_query(lat, qc[0], 2.0)
    assert {tuple(n) for n in d.nodes} <= {tuple(n) for n in ev.node_index}


def test_cli_doors_agree_on_a_filtered_program(tmp_path):
    """The same kept set through ple ir, ple eval, ple info and the beam-lattice 3MF."""
    lat = CASES["cascade"]
    save_ir(lat, tmp_path / "c.json")
    ev = lat.evaluate()
    assert main(["eval", str(tmp_path / "c.json"), "--out", str(tmp_path / "c.npz")]) == 0
    with np.load(tmp_path / "c.npz") as z:
        assert _sets(type(ev)(z["node_index"], z["center"], z["radius"], z["beam_index"], z["beam_nodes"])) == _sets(ev)
    assert main(["mesh", str(tmp_path / "c.json"), "--beam-lattice", "--out", str(tmp_path / "c.3mf")]) == 0
    with zipfile.ZipFile(tmp_path / "c.3mf") as z:
        xml = z.read("3D/3dmodel.model").decode()
    verts = np.array(re.findall(r'<vertex x="([^"]+)" y="([^"]+)" z="([^"]+)"', xml), float)
    balls = np.array(re.findall(r'<b2:ball vindex="(\d+)"', xml), int)  # the balls' vertices (a mesh may ride along)
    beams = np.array(re.findall(r'<b:beam v1="(\d+)" v2="(\d+)"', xml), int)
    assert len(balls) == len(ev.center)
    node_of = {}  # vertex index -> row of the kept evaluation, by position (float32 in the file)
    for v in balls:
        d = np.linalg.norm(ev.center - verts[v], axis=1)
        assert d.min() < 1e-5
        node_of[v] = int(np.argmin(d))
    assert sorted(node_of.values()) == list(range(len(ev.center)))
    assert {tuple(sorted((node_of[a], node_of[b]))) for a, b in beams} == {tuple(sorted(x)) for x in ev.beam_nodes}


def test_volume_of_a_filtered_lattice_agrees_with_monte_carlo(rng):
    """A clean cubic lattice with a stencil: ple info's volume (kept hubs) vs Monte Carlo of the
    union of the kept balls and beams, within 4σ; and vs the closed form when nothing is removed."""
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.22)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    for setter in (lat.set_u, lat.set_v, lat.set_w):
        setter(4, Translation(Vec(*np.eye(3)[[lat.set_u, lat.set_v, lat.set_w].index(setter)])))
    full = lattice_info(lat)
    everything = lattice_info(lat.with_filter(Stencil(np.ones((1, 1, 1), bool))))
    assert np.isclose(everything["volume"], full["volume"], rtol=1e-9)  # kept-hub sums = closed form
    kept = lat.with_filter(Stencil.named("faces", 2))
    info = lattice_info(kept)
    ev = kept.evaluate()
    lo, hi = ev.center.min(axis=0) - 0.3, ev.center.max(axis=0) + 0.3
    n = 200_000
    p = lo + (hi - lo) * rng.random((n, 3))
    inside = np.zeros(n, bool)
    for c, r in zip(ev.center, ev.radius):
        inside |= np.einsum("ij,ij->i", p - c, p - c) <= r * r
    for s, e in ev.beam_nodes:
        box = np.all((p >= np.minimum(ev.center[s], ev.center[e]) - 0.25)
                     & (p <= np.maximum(ev.center[s], ev.center[e]) + 0.25), axis=1) & ~inside
        inside[box] |= beam_distance(p[box], ev.center[s], ev.radius[s], ev.center[e], ev.radius[e]) <= 0
    frac = inside.mean()
    vol, sigma = frac * np.prod(hi - lo), np.sqrt(frac * (1 - frac) / n) * np.prod(hi - lo)
    assert abs(info["volume"] - vol) < 4 * sigma, (info["volume"], vol, sigma)
    assert info["volume"] < full["volume"]


@pytest.mark.parametrize("bad, where", [
    ({"stencil": {"shape": [2, 2], "cells": [1, 0, 0, 1]}}, "filter.stencil.shape"),
    ({"stencil": {"shape": [1, 1, 2], "cells": [1, 2]}}, "filter.stencil.cells"),
    ({"stencil": {"shape": [1, 1, 1], "cells": [1], "period": 3}}, "filter.stencil.period"),
    ({"lil": {}}, "filter.lil.coarse"),
    ({"lil": {"coarse": {"format": "ple-lattice/1", "nodes": [{"center": [0, 0, 0], "radius": -1}]}}},
     "filter.lil.coarse.nodes[0]"),
    ({"implicit": {"kind": "gyroide"}}, "filter.implicit.kind"),
    ({"implicit": {"kind": "gyroid", "level": "nan"}}, "filter.implicit.level"),
    ({"implicit": {"kind": "fourier", "n": 4, "freqs": [[1, 0]], "coeffs": [[1, 0]]}}, "filter.implicit.freqs[0]"),
    ({"and": []}, "filter.and"),
    ({"or": [{"stencil": {"shape": [1, 1, 1], "cells": [1]}}, {"xor": {}}]}, "filter.or[1].xor"),
    ({"not": {"stencil": 3}}, "filter.not.stencil"),
    ({"stencil": {"shape": [1, 1, 1], "cells": [1]}, "lil": {}}, "filter"),
])
def test_every_malformed_filter_field_exits_2_naming_it(tmp_path, capsys, bad, where):
    data = lattice_to_ir(CASES["stencil"].unfiltered())
    data["filter"] = bad
    (tmp_path / "bad.json").write_text(json.dumps(data))
    assert main(["info", str(tmp_path / "bad.json")]) == 2
    err = capsys.readouterr().err
    assert where in err, err
    with pytest.raises(Exception, match=re.escape(where.split("filter.", 1)[-1].split("[")[0])):
        filter_from_dict(bad)
