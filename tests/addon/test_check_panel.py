"""The add-on's Check panel (``ple_addon/features/check.py``), installed from the built zip into headless
bpy 5.0.1 through the helpers of ``test_addon`` (in the test run's one Blender worker). Truth: the core
installed in the environment (an independent copy of the vendored one) run on the same program,
and a brute-force test of all element pairs."""

from __future__ import annotations

import json

import numpy as np
import pytest
import test_addon as base

# a cubic lattice with both face diagonals of every xy face: they cross at the face centres
CROSSING = '''"""Crossing face diagonals: unclean by construction."""


def lattice(r: Range(0.02, 0.2) = 0.06):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), r)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(4, Translation(Vec(1, 0, 0)))
    lat.set_v(4, Translation(Vec(0, 1, 0)))
    lat.set_w(3, Translation(Vec(0, 0, 1)))
    return lat
'''

CASES = ["report", "show_and_errors", "filtered_whole"]


@pytest.mark.parametrize("case", CASES)
def test_check_panel_case(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
def crossing_rig(region=(3, 3, 3)):
    text = base.bpy.data.texts.new("crossing.py")
    text.from_string(CROSSING)
    assert base.bpy.ops.ple.lattice_add(source="TEXT", text="crossing.py", name="crossing", region=region) \
        == {"FINISHED"}
    return base.bpy.context.active_object


def all_pairs_unclean(ev) -> int:
    """Beam pairs sharing no ball whose cone-beams overlap, over every pair (brute force)."""
    from ple.queries.overlaps import pair_gaps

    bn = ev.beam_nodes
    i, j = np.triu_indices(len(bn), 1)
    keep = ~(bn[i][:, :, None] == bn[j][:, None, :]).any(axis=(1, 2))
    i, j = i[keep], j[keep]
    one = np.ones(len(i), np.int64)
    c, r = ev.center, ev.radius
    _, over, _ = pair_gaps(one, c[bn[i, 0]], r[bn[i, 0]], (c[bn[i, 1]], r[bn[i, 1]]),
                           one, c[bn[j, 0]], r[bn[j, 0]], (c[bn[j, 1]], r[bn[j, 1]]))
    return int(over.sum())


def case_report():
    from ple.measure.check import check_report
    from ple.measure.moments import mass_properties

    bpy, core = base.bpy, base.core
    rig = crossing_rig()
    rig.ple_check.min_feature = 0.2
    assert bpy.ops.ple.check() == {"FINISHED"}
    got = json.loads(rig.ple_check.report)
    lat = core.compile_program(CROSSING).run()
    want = check_report(lat, "0:3,0:3,0:3", 0.2, None)
    assert got["region"] == "0:3,0:3,0:3" and got["ok"] is False
    for key, rule in want["rules"].items():
        assert got["rules"][key]["ok"] == rule["ok"] and got["rules"][key]["count"] == rule["count"], key
    # the crossing diagonals of the 2 × 2 xy faces of each of 3 layers, and nothing else
    ev = lat.evaluate("0:3,0:3,0:3")
    assert got["rules"]["clean"]["count"] == all_pairs_unclean(ev) == 12
    assert got["rules"]["thinnest_beam"]["ok"] is False  # diameter 0.12 < 0.2
    mass = mass_properties(lat, "0:3,0:3,0:3")
    assert got["mass"]["volume"] == pytest.approx(mass["volume"], rel=1e-12)
    assert np.allclose(got["mass"]["centroid"], mass["centroid"]) and np.allclose(mass["centroid"], 1, atol=1e-3)
    seen = []  # the panel draws every line of the report, with a Show button per listed offender
    cls = bpy.types.PLE_PT_check
    assert cls.poll(bpy.context)
    cls.draw(type("P", (), {"layout": base.CheckedLayout(seen), "rig": cls.rig})(), bpy.context)
    assert {"scope", "min_feature", "max_slenderness", "ple.check", "ple.check_show"} <= set(seen)


def case_show_and_errors():
    from ple.measure.check import offender_region

    bpy, core = base.bpy, base.core
    rig = crossing_rig(region=(4, 4, 3))
    base.fails(bpy.ops.ple.check_show, "no check report", rule="clean", index=0)
    assert bpy.ops.ple.check() == {"FINISHED"}
    worst = json.loads(rig.ple_check.report)["rules"]["clean"]["worst"]
    assert bpy.ops.ple.check_show(rule="clean", index=0) == {"FINISHED"}
    lat = core.compile_program(CROSSING).run()
    region = offender_region(lat, worst[0])
    assert (tuple(rig.ple.region_min), tuple(rig.ple.region_max)) == ((region.i0, region.j0, region.k0),
                                                                      (region.i1, region.j1, region.k1))
    base.assert_region_is(rig, lat, region)  # the drawing shows the offending beams
    a, b = (np.array(worst[0][s]["beam"][:3]) for s in ("a", "b"))
    assert np.all(np.minimum(a, b) >= [region.i0, region.j0, region.k0])
    base.fails(bpy.ops.ple.check_show, "no offender", rule="clean", index=99)
    rig.ple.region_min, rig.ple.region_max = (2, 2, 2), (2, 2, 2)
    base.fails(bpy.ops.ple.check, "region is empty")


def case_filtered_whole():
    from ple.filters.stencil import Stencil
    from ple.measure.moments import mass_properties

    bpy, core = base.bpy, base.core
    rig = crossing_rig()
    assert bpy.ops.ple.stencil_filter(rig=rig.name, shape=(2, 1, 1), bits="10") == {"FINISHED"}
    rig.ple_check.scope = "WHOLE"
    assert bpy.ops.ple.check() == {"FINISHED"}
    got = json.loads(rig.ple_check.report)
    lat = core.compile_program(CROSSING).run()
    lat.set_filter(Stencil(np.array([1, 0]).reshape(2, 1, 1)))
    ev = lat.evaluate()
    assert got["filtered"] and got["region"] == "0:4,0:4,0:3"
    assert got["nodes"] == len(ev.node_index) == 24 and got["beams"] == len(ev.beam_nodes)
    # every x strut lost an end: the kept balls (even i) are joined along y and z only; no diagonals
    assert got["rules"]["clean"]["ok"] and all_pairs_unclean(ev) == 0
    assert got["rules"]["components"]["count"] == 2
    assert got["mass"]["volume"] == pytest.approx(mass_properties(lat)["volume"], rel=1e-12)
