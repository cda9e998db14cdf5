"""Live drawing (issue 39): balls and beams drawn as instances of one mesh each, a move of G that
moves the region's object and rewrites nothing, and the hull a live move draws of a region too
big to draw in full, until the moves pause.

Truth: the core package of the environment (an independent copy of the vendored one) and the
geometry of the instances as Blender evaluated them (``depsgraph.object_instances``).
"""

from __future__ import annotations

import numpy as np
import pytest
import test_addon as base
from test_addon import new_rig, part, region_arrays, update  # noqa: F401 - bpy-side helpers

CASES = ["instances_are_the_balls_and_cone_beams", "move_of_g_moves_the_object_only",
         "move_of_g_through_a_filter_redraws", "live_hull_then_settle"]


@pytest.mark.parametrize("case", CASES)
def test_live_drawing(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
bpy = ple_ext = core = None


def instances(obj) -> list[np.ndarray]:
    """World vertices of every instance the region object's geometry nodes made."""
    dg = bpy.context.evaluated_depsgraph_get()
    out = []
    for inst in dg.object_instances:
        if inst.is_instance and inst.parent is not None and inst.parent.original == obj:
            me = inst.object.data
            co = np.zeros(len(me.vertices) * 3)
            me.vertices.foreach_get("co", co)
            m = np.array(inst.matrix_world)
            out.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
    return out


def world(rig, pts):
    m = np.array(rig.matrix_world)
    return pts @ m[:3, :3].T + m[:3, 3]


def case_instances_are_the_balls_and_cone_beams():
    """Every ball is an instance whose vertices lie on its sphere; every beam one whose vertices
    lie on the cone between its two end balls (the taper rounded to eighths of the larger radius)."""
    rig = new_rig("fig6_3", region=(2, 2, 2))
    lat = core.load_lattice("fig6_3")
    lo = tuple(rig.ple.region_min)
    ev = lat.evaluate(",".join(f"{a}:{a + 2}" for a in lo))
    centers, radii = world(rig, ev.center), ev.radius  # the rig sits at the cursor (origin): no scale
    got = instances(part(rig, "region"))
    assert len(got) == len(ev.center) + len(ev.beam_nodes)
    balls = set()
    beams = set()
    tapered = 0
    for pts in got:
        mid = pts.mean(axis=0)
        d = np.linalg.norm(centers - mid, axis=1)
        n = int(d.argmin())
        on_sphere = np.abs(np.linalg.norm(pts - centers[n], axis=1) - radii[n])
        if d[n] < 1e-4 and on_sphere.max() < 1e-4 * max(1.0, radii[n]):
            balls.add(n)
            continue
        # a beam: its axis joins two ball centres, its end rings have their radii
        a, b = centers[ev.beam_nodes[:, 0]], centers[ev.beam_nodes[:, 1]]
        k = int(np.linalg.norm(0.5 * (a + b) - mid, axis=1).argmin())
        n1, n2 = ev.beam_nodes[k]
        axis = centers[n2] - centers[n1]
        t = (pts - centers[n1]) @ axis / (axis @ axis)
        assert np.all((np.abs(t) < 1e-4) | (np.abs(t - 1) < 1e-4)), t  # every vertex on an end ring
        ring = np.linalg.norm(pts - centers[n1] - t[:, None] * axis, axis=1)
        want = np.where(t < 0.5, radii[n1], radii[n2])
        big = max(radii[n1], radii[n2])
        assert np.abs(ring - want).max() <= big / 16 + 1e-5, (ring, want)
        tapered += not np.isclose(radii[n1], radii[n2])
        beams.add(k)
    assert balls == set(range(len(ev.center))) and beams == set(range(len(ev.beam_nodes)))
    assert tapered  # fig6_3's beams join balls of different radii: the cones are not all cylinders


def move_g(rig, angle=0.3, shift=(1.5, -0.5, 0.25), scale=1.2):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:3, :3] = scale * np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    m[:3, 3] = shift
    from mathutils import Matrix

    part(rig, "G").matrix_basis = Matrix(m.tolist())
    update()
    return core.Similarity.from_matrix(m)


def placed(name, sim):
    lat = core.load_lattice(name)
    lat.set_placement(sim)
    return lat


def data_of(obj):
    me = obj.data
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    return co


def case_move_of_g_moves_the_object_only():
    rig = new_rig("cubic", region=(4, 3, 2))
    region = part(rig, "region")
    before = data_of(region)
    cage_before = [tuple(p.co) for sp in part(rig, "cage").data.splines for p in sp.points]
    sim = move_g(rig)
    assert np.array_equal(data_of(region), before)  # nothing rewritten
    assert [tuple(p.co) for sp in part(rig, "cage").data.splines for p in sp.points] == cage_before
    assert np.allclose(np.array(region.matrix_basis), sim.matrix, atol=1e-6)
    assert np.allclose(np.array(part(rig, "cage").matrix_basis), sim.matrix, atol=1e-6)
    base.assert_region_is(rig, placed("cubic", sim), "0:4,0:3,0:2")  # what is drawn is the moved lattice
    # a later move of U redraws in the same (lattice) coordinates, still placed by G
    u = part(rig, "u")
    u.location = (u.location[0] + 0.1, u.location[1], u.location[2])
    update()
    assert not np.array_equal(data_of(region), before)
    want = placed("cubic", sim)
    want.set_u(10, core.Translation(core.Vec(1.1, 0, 0)))  # U's frame moved in G's coordinates
    base.assert_region_is(rig, want, "0:4,0:3,0:2")
    bpy.data.objects.remove(region)  # a script deleted the drawing: the next move of G draws it again
    sim = move_g(rig, angle=-0.2, shift=(0.5, 0.5, 0.0), scale=0.9)
    want = placed("cubic", sim)
    want.set_u(10, core.Translation(core.Vec(1.1, 0, 0)))
    base.assert_region_is(rig, want, "0:4,0:3,0:2")


def case_move_of_g_through_a_filter_redraws():
    """A stencil reads indices only, but a body or a LiL filter reads placed points: any panel
    filter makes a move of G evaluate again (never a stale kept set)."""
    rig = new_rig("cubic", region=(4, 4, 1))
    rig.ple.stencil_shape = (2, 2, 1)
    rig.ple.stencil_bits = "1001"
    rig.ple.filter_kind = "STENCIL"
    update()
    sim = move_g(rig)
    region = part(rig, "region")
    assert np.allclose(np.array(region.matrix_basis), np.eye(4))  # drawn placed, in the rig's coordinates
    lat = placed("cubic", sim).with_filter(core.Stencil(np.array([1, 0, 0, 1], bool).reshape(2, 2, 1)))
    base.assert_region_is(rig, lat, "0:4,0:4,0:1")


def cubic(n, step):
    lat = core.load_lattice("cubic")
    lat.set_u(n, core.Translation(core.Vec(step, 0, 0)))
    lat.set_v(n, core.Translation(core.Vec(0, 1, 0)))
    lat.set_w(n, core.Translation(core.Vec(0, 0, 1)))
    return lat


def case_live_hull_then_settle():
    sync, drawing = ple_ext.rig.sync, ple_ext.rig.drawing
    st_of = ple_ext.rig.model.state_of
    old = drawing.LIVE_ELEMENTS
    drawing.LIVE_ELEMENTS = 500  # a 6 x 6 x 6 region has 216 balls and 540 beams, its hull 152 and 300
    try:
        rig = new_rig("cubic", region=(6, 6, 6))
        base.assert_region_is(rig, cubic(10, 1.0), "0:6,0:6,0:6")  # drawn in full: not a live move
        rig.ple.counts = (6, 6, 6)  # the counts slider is live too: the hull until the drag pauses
        update()
        assert st_of(rig).hull_drawn and len(region_arrays(rig)[0]) == 152
        sync.settle()
        base.assert_region_is(rig, cubic(6, 1.0), "0:6,0:6,0:6")
        u = part(rig, "u")
        u.location = (u.location[0] + 0.05, u.location[1], u.location[2])
        update()  # the depsgraph handler: a live move
        lat = cubic(6, 1.05)
        ev = lat.evaluate("0:6,0:6,0:6")
        g = ev.node_index[:, :3]
        hull = ((g == 0) | (g == 5)).any(axis=1)
        co, rad, ed = region_arrays(rig)
        assert np.allclose(co, ev.center[hull], atol=1e-5) and np.allclose(rad, ev.radius[hull], rtol=1e-5)
        both = hull[ev.beam_nodes].all(axis=1)
        row = np.cumsum(hull) - 1
        assert np.array_equal(ed, row[ev.beam_nodes[both]])  # the beams between hull groups
        assert st_of(rig).hull_drawn and bpy.app.timers.is_registered(sync.settle)
        sync.settle()  # what the timer does once the moves pause
        base.assert_region_is(rig, lat, "0:6,0:6,0:6")
        assert not st_of(rig).hull_drawn
        drawing.LIVE_ELEMENTS = 100  # even the hull is too many: thinned balls alone
        u.location = (u.location[0] + 0.05, u.location[1], u.location[2])
        update()
        co, rad, ed = region_arrays(rig)
        assert 0 < len(co) <= 100 and len(ed) == 0
        sync.settle()
        base.assert_region_is(rig, cubic(6, 1.1), "0:6,0:6,0:6")
    finally:
        drawing.LIVE_ELEMENTS = old
        if bpy.app.timers.is_registered(sync.settle):
            bpy.app.timers.unregister(sync.settle)
