"""Degenerate junctions (CHoCC paper 001_ §3–6): each gets a defined treatment or a PleError that
names the hub (node index i, j, k, n), its beam-patterns and the geometric reason — never a
traceback. Every case is built from its geometry: coplanar, antipodal and coincident beam
directions at a hub, zero-length beams, a ball inside another, near-singular Apollonius systems
and values that are not numbers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from ple import Lattice, Translation
from ple.algebra.vectors import Pt, Vec
from ple.cli.main import main
from ple.errors import PleError
from ple.io.irfile import load_ir, save_ir
from ple.meshing.achocc import CENTRE_MARGIN, JunctionError, _visible_face, hub_geometry
from ple.meshing.chocc import _null_space_planes, apollonius_planes, chocc
from ple.meshing.hubs import hub_template
from ple.meshing.tessellate import tessellate
from union_oracle import union_volume

DATA = Path(__file__).parent / "data"
X, Y, Z = np.eye(3)


def _lattice(nodes, beams, counts=(3, 3, 3)) -> Lattice:
    """nodes: (centre, radius) in a unit cell; beams: (n1, n2, offset); U, V, W unit translations."""
    lat = Lattice()
    for c, r in nodes:
        lat.add_node(c, r)
    for n1, n2, off in beams:
        lat.add_beam(n1, n2, *off)
    for axis, (name, count) in enumerate(zip("uvw", counts)):
        getattr(lat, f"set_{name}")(count, Translation(np.eye(3)[axis]))
    return lat


def _assert_meshes_the_union(lat: Lattice, styles=(("cnt", 0), ("refined", 4))) -> None:
    """Watertight and oriented in each style; the refined volume within 1 % + 4σ of the Monte
    Carlo volume of the exact union (level 4 rings have ≥ 48 vertices: an inscribed regular
    48-gon misses 0.3 % of its disk)."""
    ev = lat.evaluate()
    est, err = union_volume(ev.center, ev.radius, ev.beam_nodes, 16000)
    for style, levels in styles:
        mesh = tessellate(lat, style=style, levels=levels)
        assert mesh.is_watertight and mesh.is_winding_consistent, style
        assert np.isfinite(mesh.vertices).all()
        if style == "refined":
            assert abs(mesh.volume / est - 1) <= 0.01 + 4 * err / est, (mesh.volume, est, err)


def _centre_inside(hub) -> bool:
    return _visible_face(hub.chocc)[0] > CENTRE_MARGIN


# ----- the LiL-filtered two-ball lattice: T-junctions ------------------------------------------
def test_t_junction_gets_its_point_circle_on_the_face_normal():
    """A hub with beams +x, +z, −z (a T: the three directions in a half-plane, two of them
    antipodal): the CNT quad between the ±z contact circles is a plane through the centre, and by
    symmetry its centroid is the centre itself, so the off-centre fix's ray "from the centroid
    through the centre" is 0/0 (round-off gave it any direction, or NaN and a non-converging SVD).
    The point circle goes on the face's outward normal, −x."""
    r = 0.14210617183098478  # the fixture's hub a at a border of its LiL filter
    hub = hub_geometry(r, np.array([X, Z, -Z]), np.full(3, r),
                       np.array([1.155238138466975, 1.071434543460442, 1.0714345434604429]))
    assert hub.chocc.n == 4 and np.allclose(hub.chocc.normals[3], -X, atol=1e-12)
    assert np.isfinite(hub.chocc.points).all() and _centre_inside(hub)


@pytest.mark.parametrize("dirs", [[X, Z, -Z], [X, Y, -Y], [Y, X, -X, Z]], ids=["xz", "xy", "xyz"])
def test_half_space_junctions_contain_their_centre(dirs):
    """Beams in a closed half-space with an antipodal pair on its boundary: the fixed hub
    contains its centre (refinement projects from it), every vertex finite."""
    dirs = np.array(dirs, float)
    hub = hub_geometry(0.1, dirs, np.full(len(dirs), 0.1), np.ones(len(dirs)))
    assert np.isfinite(hub.chocc.points).all() and _centre_inside(hub)


def test_fixture_region_with_t_junctions_meshes():
    """Groups 0:2, 0, 4:7 of the attached lattice hold its T-junction hubs (0, 0, 5, 0), (0, 0, 6, 0),
    (1, 0, 5, 0) and (1, 0, 6, 0) (LiL keeps +x, +z, −z of their six beams); they mesh closed in
    every closed style. (No volume here: beams leaving a region end at their hub's contact disk.)"""
    lat = load_ir(DATA / "issue_lil_two_balls.json")
    for style, levels in (("cnt", 0), ("chocc", 0), ("refined", 1)):
        mesh = tessellate(lat, "0:2,0:1,4:7", style=style, levels=levels)
        assert mesh.is_watertight and mesh.is_winding_consistent and np.isfinite(mesh.vertices).all(), style


def test_folded_refined_hubs_of_the_fixture_go_to_unions():
    """Column i = 3 of the attached lattice: LiL leaves hubs whose refined surface turns back on
    itself (no separating plane is needed: one hub's faces meet each other). Such a junction is
    not star-shaped and the exact check finds its folds (``hubs.folded``), so it is left to a
    local union: the region's refined mesh is closed and has no self-intersecting pair (it had
    135 at two levels)."""
    from ple.meshing.selfcheck import self_intersections

    lat = load_ir(DATA / "issue_lil_two_balls.json")
    mesh = tessellate(lat, "2:5,0:5,0:2", style="refined", levels=2)
    rep = mesh.metadata["ple_unclean"]
    assert rep.shrunk_hubs > 0  # the folded junctions, now unclean
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent and len(self_intersections(v, f)) == 0


def test_contact_rings_out_of_order_send_their_beams_to_unions():
    """CHoCC junctions of the attached lattice whose contact ring has a vertex behind its
    predecessor about the beam: the strip zipped by angle would fold (37 self-intersecting pairs
    on beam (3, 0, 4)-(3, 1, 4) before). Such a beam is a pair with itself, meshed by a union:
    the chocc mesh is closed, oriented and has no self-intersecting pair (exact). Whether a ring
    runs out of order depends on the last bits of the CPU's sin and cos (seen on one machine, not
    on another): where the templates have one, a beam is paired with itself."""
    from ple.meshing.selfcheck import self_intersections
    from ple.meshing.tessellate import Tessellator

    lat = load_ir(DATA / "issue_lil_two_balls.json")
    mesh = tessellate(lat, "2:5,0:3,3:6", style="chocc")
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent and len(self_intersections(v, f)) == 0
    region = lat.region("2:5,0:3,3:6")
    tess = Tessellator(lat, region, "chocc", 0, 16)
    tess.instances(np.asarray(lat.evaluate(region).node_index, np.int64))
    rep = mesh.metadata["ple_unclean"]
    n = len(rep.shrunk)
    pairs = np.asarray(rep.element_pairs).reshape(-1, 2)
    out_of_order = not tess._rings_in_order().all()
    assert out_of_order == bool(((pairs[:, 0] == pairs[:, 1]) & (pairs[:, 0] >= n)).any())  # a beam paired with itself


def test_rings_in_order_sees_a_vertex_out_of_place():
    """``_rings_in_order``: every contact ring of a cubic lattice's hub runs one way about its
    beam; moving one ring vertex back past its predecessor is seen."""
    from ple.meshing.tessellate import Tessellator

    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.2)
    for off in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
        lat.add_beam(a, a, *off)
    for axis in "uvw":
        getattr(lat, f"set_{axis}")(3, Translation(Vec(*[float(axis == x) for x in "uvw"])))
    tess = Tessellator(lat, lat.region(), "chocc", 0, 16)
    tess.instances(np.asarray(lat.evaluate(lat.region()).node_index, np.int64))
    assert tess._rings_in_order().all()
    tpl, slot_of = tess.tpl_list[0]
    ring = np.asarray(tpl.rings[slot_of[0]], np.int64)
    tpl.rings[slot_of[0]] = ring[[0, 2, 1, *range(3, len(ring))]]  # the second vertex behind the third
    assert not tess._rings_in_order()[0, 0]


# ----- coplanar and antipodal beam directions --------------------------------------------------
def test_square_grid_cross_t_and_l_junctions():
    """A one-layer square grid: cross hubs (4 coplanar beams: four circles on one supporting
    plane, a tie), T hubs on its edges and L hubs at its corners."""
    _assert_meshes_the_union(_lattice([([0, 0, 0], 0.12)], [(0, 0, (1, 0, 0)), (0, 0, (0, 1, 0))], (3, 3, 1)))


def test_honeycomb_three_coplanar_beams():
    """Two balls per cell, each with three coplanar beams 120° apart (the Appendix A system is
    singular: Eq. A.3's null space)."""
    s = np.sqrt(3)
    lat = Lattice()
    a = lat.add_node([0, 0, 0], 0.08)
    b = lat.add_node([1, 0, 0], 0.08)
    lat.add_beam(a, b, 0, 0, 0)
    lat.add_beam(b, a, 1, 0, 0)
    lat.add_beam(b, a, 0, 1, 0)
    lat.set_u(2, Translation([3, 0, 0]))
    lat.set_v(2, Translation([-1.5, 1.5 * s, 0]))
    lat.set_w(1, Translation([0, 0, 1]))
    ends = lat.evaluate()
    assert len(ends.beam_nodes) == 8
    _assert_meshes_the_union(lat)


def test_straight_chain_antipodal_beams():
    """A chain of balls: inner hubs have two antipodal beams (CHoCC case n = 2 with two point
    circles), end hubs one beam (a tripod)."""
    _assert_meshes_the_union(_lattice([([0, 0, 0], 0.15)], [(0, 0, (1, 0, 0))], (4, 1, 1)))


def test_antipodal_pairs_with_different_radii():
    """Antipodal beams to balls of other radii (cones narrowing and widening at one hub)."""
    lat = _lattice([([0, 0, 0], 0.14), ([0.5, 0, 0], 0.07)], [(0, 1, (0, 0, 0)), (1, 0, (1, 0, 0)),
                                                            (0, 0, (0, 1, 0))], (2, 2, 1))
    _assert_meshes_the_union(lat)


# ----- coincident directions, zero-length beams, a ball inside another -------------------------
def _error(lat: Lattice) -> str:
    with pytest.raises(PleError) as e:
        tessellate(lat, style="cnt")
    return str(e.value)


def test_a_repeated_beam_pattern_names_the_hub_and_both_patterns():
    """Patterns (1, 0, 0) and (−1, 0, 0) of one ball are one beam twice: at every hub two beams
    leave in the same direction."""
    msg = _error(_lattice([([0, 0, 0], 0.1)], [(0, 0, (1, 0, 0)), (0, 0, (0, 1, 0)), (0, 0, (-1, 0, 0))]))
    assert "hub (i, j, k, n) = (0, 0, 0, 0)" in msg and "same direction" in msg
    assert "beam-patterns 0 (0 -> 0 (1, 0, 0))" in msg and "2 (0 -> 0 (-1, 0, 0), incoming)" in msg


def test_balls_in_line_are_coincident_directions():
    """Beams to the next and the second next ball along x leave in one direction (the shorter
    lies inside the longer)."""
    msg = _error(_lattice([([0, 0, 0], 0.1)], [(0, 0, (1, 0, 0)), (0, 0, (2, 0, 0))], (4, 1, 1)))
    assert "(0, 0, 0, 0)" in msg and "same direction" in msg and "(2, 0, 0)" in msg


def test_near_coincident_directions_are_unclean_and_united():
    """Two beams 0.5° apart: their caps overlap at any r⁺, so the junction is shrunk (unclean)
    and its neighbourhood is meshed as the exact union of its balls and cone-beams."""
    t = np.radians(0.5)
    lat = _lattice([([0, 0, 0], 0.06), ([1, np.tan(t), 0], 0.05)],
                   [(0, 0, (1, 0, 0)), (0, 1, (0, 0, 0))], (2, 1, 1))
    assert len(tessellate(lat, style="cnt").metadata["ple_unclean"].nodes)
    _assert_meshes_the_union(lat)


@pytest.mark.parametrize("angle", [1e-8, 1e-6, 1e-3])
def test_coincidence_threshold(angle):
    """Below about 1e-8 rad two directions are one for the ACHoCC (cos θ rounds to 1): an error;
    above it the hub builds, unclean (its caps shrunk to their share, finite)."""
    nb = np.array([X, [1, np.tan(angle), 0], Y, Z])
    if angle < 1e-7:
        with pytest.raises(JunctionError, match="same direction"):
            hub_template(np.zeros(3), 0.06, nb, [0.06, 0.05, 0.06, 0.06], "cnt", 0, 16)
    else:
        hub = hub_template(np.zeros(3), 0.06, nb, [0.06, 0.05, 0.06, 0.06], "cnt", 0, 16)
        assert not hub.geometry.clean and np.isfinite(hub.vertices).all()


def test_zero_length_beam_names_the_hub():
    """Ball b of group i sits on ball a of group i + 1: the beam a → b with offset −1 has length 0."""
    msg = _error(_lattice([([0, 0, 0], 0.1), ([1, 0, 0], 0.08)], [(0, 0, (1, 0, 0)), (0, 1, (-1, 0, 0))]))
    assert "(i, j, k, n) = (1, 0, 0, 0)" in msg and "length 0" in msg and "beam-pattern 1" in msg


@pytest.mark.parametrize("r_small, length", [(0.05, 0.1), (0.2, 0.05)])
def test_ball_inside_its_beams_other_ball(r_small, length):
    """|r1 − r2| ≥ L: the hull of the two balls is the larger ball, a cone-beam without a cone."""
    msg = _error(_lattice([([0, 0, 0], 0.3), ([0, length, 0], r_small)], [(0, 0, (1, 0, 0)), (0, 1, (0, 0, 0))]))
    assert "(0, 0, 0, 0)" in msg or "(0, 0, 0, 1)" in msg
    assert "inside the other ball of its beam" in msg and "beam-pattern 1" in msg


def test_ball_inside_an_unjoined_ball_is_united():
    """A small ball inside a big one that no beam joins: the detector flags the overlap and the
    union path meshes it (the union is the big ball with its beams)."""
    lat = _lattice([([0, 0, 0], 0.2), ([0.05, 0.02, 0], 0.04)], [(0, 0, (1, 0, 0)), (1, 1, (0, 1, 0))], (2, 2, 1))
    mesh = tessellate(lat, style="cnt")
    assert len(mesh.metadata["ple_unclean"].nodes) and mesh.is_watertight


def test_cli_exits_2_naming_the_hub(tmp_path, capsys):
    src = tmp_path / "zero.json"
    save_ir(_lattice([([0, 0, 0], 0.1), ([1, 0, 0], 0.08)], [(0, 0, (1, 0, 0)), (0, 1, (-1, 0, 0))]), src)
    out = tmp_path / "zero.stl"
    assert main(["mesh", str(src), "--style", "cnt", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "(i, j, k, n) = (1, 0, 0, 0)" in err and "length 0" in err and "Traceback" not in err
    assert not out.exists()
    assert json.loads(src.read_text())["format"] == "ple-lattice/1"


def test_cli_refuses_a_beam_pattern_given_twice_before_meshing(tmp_path, capsys):
    """The same beams given twice (a pattern and its reverse) are refused when the file is read
    (``budget.check_lattice``), naming both beam-patterns, before any hub is built."""
    src = tmp_path / "twice.json"
    save_ir(_lattice([([0, 0, 0], 0.1)], [(0, 0, (1, 0, 0)), (0, 0, (-1, 0, 0))], (2, 2, 2)), src)
    out = tmp_path / "twice.stl"
    assert main(["mesh", str(src), "--style", "cnt", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "beams[1]" in err and "repeats beams[0]" in err and "Traceback" not in err
    assert not out.exists()


# ----- near-singular Apollonius systems and values that are not numbers ------------------------
@pytest.mark.parametrize("tilt", [0.0, 1e-14, 1e-9, 1e-5, 1e-3])
def test_nearly_coplanar_normals_give_tangent_planes(tilt):
    """Three cap centres (almost) on one great circle: whichever branch solves it, both planes
    are tangent to all three circles (N·N_i = cos(α + α_i))."""
    n = np.array([X, [np.cos(2.0), np.sin(2.0), tilt], [np.cos(4.0), np.sin(4.0), -tilt]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    alpha = np.array([0.3, 0.2, 0.25])
    pn, pa = apollonius_planes(n[None], alpha[None])
    assert np.isfinite(pn).all()
    assert np.allclose(pn[0] @ n.T, np.cos(pa[0][:, None] + alpha[None]), atol=1e-9)


def test_non_finite_circles_are_an_error_not_an_svd_failure():
    n = np.array([[X, Y, [np.nan, 0, 1]]])
    pn, pa = _null_space_planes(n, np.full((1, 3), 0.1))  # LAPACK would not converge
    assert np.isnan(pn).all() and np.isnan(pa).all()
    with pytest.raises(PleError, match="not a finite number"):
        chocc([X, Y, [np.nan, 0, 1]], [0.1, 0.1, 0.1])


@pytest.mark.parametrize("where", ["direction", "radius", "length"])
def test_non_finite_hub_input_is_a_junction_error(where):
    dirs, other, lengths = np.array([X, Y, Z]), np.full(3, 0.1), np.ones(3)
    radius = 0.1
    if where == "direction":
        dirs[1, 0] = np.nan
    elif where == "radius":
        other[2] = np.inf
    else:
        lengths[0] = np.nan
    with pytest.raises(JunctionError, match="not a finite number"):
        hub_geometry(radius, dirs, other, lengths)
