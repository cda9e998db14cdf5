"""Local unions of unclean lattices (``ple.meshing.unions``): clusters found from the overlap
graph, each united alone and joined to the boxes of the fast path along contact rings; the
streamed file is the in-memory mesh, closed and free of self-intersections."""

from __future__ import annotations

import numpy as np
import pytest
from lattices import two_ball_hull_volume
from ple.algebra.similarity import Rotation, Translation
from ple.algebra.vectors import Pt, Vec
from ple.app.pipeline import MeshRequest, write_mesh
from ple.cli.mesh import monte_carlo_volume
from ple.io.export import read_back
from ple.meshing.selfcheck import self_intersections
from ple.meshing.tessellate import Tessellator, tessellate
from ple.meshing.unions import clusters
from ple.model.lattice import Lattice

manifold3d = pytest.importorskip("manifold3d")


def crossing(n: int, curved: bool, radius: float = 0.1) -> Lattice:
    """Crossing diagonals (1, 1, 0) and (-1, 1, 0) on a cubic lattice (curved: V a rotation)."""
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Rotation(0.02, Vec(0, 0, 1), Pt(-45, 0, 0)) if curved else Translation(Vec(0, 1, 0)))
    lat.set_w(n, Translation(Vec(0, 0, 1)))
    return lat


def test_crossing_diagonals_are_pairs_of_beams():
    """Each cell of each xy layer holds one crossing of two diagonals ((n - 1)² n of them): a
    cluster of those two beams, no hub (their junctions are clean)."""
    n = 3
    lat = crossing(n, curved=False)
    tess = Tessellator(lat, lat.region(), "cnt", 0, 16)
    report, ev = tess.find_unclean()
    cl = clusters(report, ev.beam_nodes)
    assert len(cl) == (n - 1) ** 2 * n
    pattern = np.asarray(ev.beam_index)[:, 3]
    for c in cl:
        assert len(c.hubs) == 0 and len(c.beams) == 2
        assert sorted(pattern[c.beams].tolist()) == [3, 4]  # one of each diagonal


@pytest.mark.parametrize("curved", [False, True])
def test_streamed_file_is_the_closed_union(curved, tmp_path):
    """The streamed STL (small boxes, 1 and 2 workers) holds the in-memory mesh's triangles; it
    is closed, consistently oriented, free of self-intersections, and its volume is the union's
    (Monte Carlo of balls and cone-beams)."""
    lat = crossing(3, curved)
    mesh = tessellate(lat, None, "refined", 3)
    assert mesh.metadata["ple_unclean"].clusters == 12
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent and len(self_intersections(v, f)) == 0
    est, err = monte_carlo_volume(lat, lat.region(), samples=400_000, seed=5)
    assert abs(mesh.volume / est - 1) < 0.01 + 4 * err / est
    want = _triangles(v, f)
    for workers in (1, 2):
        out = tmp_path / f"m{workers}.stl"
        info = {}
        write_mesh(MeshRequest(lat, style="refined", levels=3, max_groups=4, workers=workers), out, info=info)
        assert info["unclean"].clusters == 12
        back = read_back(out)
        assert back.is_watertight and back.is_winding_consistent
        assert np.array_equal(_triangles(np.asarray(back.vertices), np.asarray(back.faces)), want)


def _triangles(v, f) -> np.ndarray:
    """Triangles as float32 corner rows, each from its smallest corner, sorted."""
    t = np.asarray(v, np.float32).astype(float)[np.asarray(f)]
    first = np.lexsort(t.transpose(2, 0, 1)[::-1], axis=1)[:, 0]
    t = np.take_along_axis(t, ((first[:, None] + np.arange(3)) % 3)[:, :, None].repeat(3, 2), 1).reshape(len(t), 9)
    return t[np.lexsort(t.T[::-1])]


@pytest.mark.parametrize("curved", [False, True])
def test_copies_of_a_cluster_take_its_union_exactly(curved, monkeypatch):
    """The pieces of a lattice's clusters with shapes kept (``ShapeCache``) against fresh unions,
    cluster by cluster: every ring vertex is exactly the float its own copy's fast path places
    (so the seams stay exact), and the surface is the same (area to round-off; a fresh union of
    a moved copy may triangulate it otherwise). The whole mesh with kept shapes is closed, free
    of self-intersections and of the same volume. On the straight lattice most interior clusters
    are copies; on the curved one (V a rotation) the copies along W are moved, the others turned
    (then snapped to the grid: the same surface to the grid's size)."""
    import ple.meshing.unions as unions
    from ple.meshing.tessellate import leave_to_unions, union_pieces

    def pieces():
        lat = crossing(4, curved)
        tess = Tessellator(lat, lat.region(), "cnt", 0, 16, grid=2.0**-18)
        report, ev = tess.find_unclean()
        return list(union_pieces(tess, ev, leave_to_unions(tess, ev, report))), tess

    hits = []
    real_get = unions.ShapeCache.get

    def counting(self, *args):
        got = real_get(self, *args)
        hits.append(got is not None)
        return got

    monkeypatch.setattr(unions.ShapeCache, "get", counting)
    kept, tess = pieces()
    whole = tessellate(crossing(4, curved), None, "cnt")
    monkeypatch.setattr(unions.ShapeCache, "get", lambda self, *args: None)
    fresh, _ = pieces()
    plain = tessellate(crossing(4, curved), None, "cnt")
    assert sum(hits) >= 8 and len(kept) == len(fresh)
    g = tess.grid

    def off_grid(piece):  # the ring vertices: every other vertex of a piece is on the grid
        v = np.asarray(piece[0])
        return sorted(map(tuple, v[np.any(np.round(v / g) * g != v, axis=1)].tolist()))

    def area(piece):
        t = np.asarray(piece[0])[piece[1]]
        return np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum() / 2

    fresh_by_rings = {tuple(off_grid(b)): b for b in fresh}  # (the queue may settle them in another order)
    for a in kept:
        b = fresh_by_rings[tuple(off_grid(a))]  # the very same ring floats
        assert len(off_grid(a)) >= 16
        assert area(a) == pytest.approx(area(b), rel=1e-6 if not curved else 1e-4)  # turned copies: snapped
    v, f = np.asarray(whole.vertices), np.asarray(whole.faces)
    assert whole.is_watertight and whole.is_winding_consistent and len(self_intersections(v, f)) == 0
    assert whole.volume == pytest.approx(plain.volume, rel=1e-7 if not curved else 1e-5)


def _tangent_setup(seed):
    rng = np.random.default_rng(seed)
    c1, c2 = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    length = float(np.linalg.norm(c2 - c1))
    r1, r2 = rng.uniform(0.1, 0.45) * length, rng.uniform(0.1, 0.45) * length
    return c1, c2, r1, r2, length


@pytest.mark.parametrize("seed", range(6))
def test_a_beam_takes_its_balls_caps_only(seed):
    """A beam's hull takes of each ball only the cap in front of its tangent circle: with the
    balls, it is the same solid as the hull of the whole balls (and of a ring), by volume."""
    from ple.meshing.unions import _unit_vertices, beam_points, unit_ball

    unit = _unit_vertices(manifold3d)
    c1, c2, r1, r2, _ = _tangent_setup(seed)
    b1, b2 = unit * r1 + c1, unit * r2 + c2
    a = (c2 - c1) / np.linalg.norm(c2 - c1)
    e = np.cross(a, [0.3, 0.5, 0.7])
    e /= np.linalg.norm(e)
    ring = c2 + r2 * (np.cos(np.arange(12) / 2)[:, None] * e + np.sin(np.arange(12) / 2)[:, None] * np.cross(a, e))
    balls = [unit_ball(manifold3d).scale([r, r, r]).translate(list(c)) for c, r in ((c1, r1), (c2, r2))]
    for ends, centers, solids in (([b1, b2], [c1, c2], balls), ([b1, ring], [c1, None], balls[:1])):
        caps = beam_points(ends, centers)
        assert len(caps) < sum(len(x) for x in ends)
        whole = manifold3d.Manifold.hull_points(np.concatenate(ends))
        got = manifold3d.Manifold.batch_boolean([*solids, manifold3d.Manifold.hull_points(caps)], manifold3d.OpType.Add)
        want = manifold3d.Manifold.batch_boolean([*solids, whole], manifold3d.OpType.Add)
        assert abs(got.volume() / want.volume() - 1) < 1e-9


@pytest.mark.parametrize("seed", range(5))
def test_beam_hull_of_two_balls_has_the_closed_form_volume(seed):
    """Two balls and their beam united (polygonal balls, their caps' hull) hold the volume of the
    hull of the two exact balls: two spherical caps and the frustum between the tangent circles."""
    from ple.meshing.unions import _unit_vertices, beam_points, unit_ball

    unit = unit_ball(manifold3d)
    v = _unit_vertices(manifold3d)
    c1, c2, r1, r2, length = _tangent_setup(seed)
    parts = [unit.scale([r, r, r]).translate(list(c)) for c, r in ((c1, r1), (c2, r2))]
    parts.append(manifold3d.Manifold.hull_points(beam_points([v * r1 + c1, v * r2 + c2], [c1, c2])))
    got = manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add).volume()
    assert abs(got / two_ball_hull_volume(r1, r2, length) - 1) < 0.005


@pytest.mark.parametrize("style, levels", [("cnt", 0), ("refined", 4)])
def test_clusters_cut_across_free_beams_mesh_their_union(style, levels, monkeypatch):
    """A cubic 5³ with half its hubs unclean at random (as if shrunk): neighbouring unclean hubs
    form clusters, and each is cut across its free beams, so every union holds one hub. The
    pieces meet the fast path at contact rings and each other at cut rings: one closed, oriented
    mesh, free of self-intersections (exact), with the volume of the clusters united whole (to the
    cut rings' own polygons); the refined one holds the lattice's volume (Monte Carlo)."""
    import ple.meshing.tessellate as tessellate_module
    import trimesh
    from ple.bench.unclean import case_lattice
    from ple.meshing.tessellate import build_with_unions
    from ple.meshing.unclean import UncleanReport

    lat = case_lattice("tenth", 5)
    ev = lat.evaluate(lat.region())
    shrunk = np.random.default_rng(5).random(len(ev.center)) < 0.5
    report = UncleanReport(np.flatnonzero(shrunk), 0, int(shrunk.sum()), 0, 0, np.zeros((0, 2), np.int64), shrunk)
    assert max(len(c.hubs) for c in clusters(report, ev.beam_nodes)) > 4
    united = []
    real = tessellate_module.unite_stoppable

    def spy(cluster, *args):
        united.append(cluster)
        return real(cluster, *args)

    def mesh():
        tess = Tessellator(lat, lat.region(), style, levels, 16, grid=2.0**-18)
        return trimesh.Trimesh(*build_with_unions(tess, lat.evaluate(lat.region()), report), process=False)

    monkeypatch.setattr(tessellate_module, "unite_stoppable", spy)
    cut = mesh()
    assert united and max(len(c.hubs) for c in united) == 1 and any(len(c.halves) for c in united)
    v, f = np.asarray(cut.vertices), np.asarray(cut.faces)
    assert cut.is_watertight and cut.is_winding_consistent
    assert len(self_intersections(v, f)) == 0
    monkeypatch.setattr(tessellate_module, "split", lambda *args: None)
    assert abs(cut.volume / mesh().volume - 1) < 5e-3  # the cut rings are polygons of their own
    if style == "refined":
        est, err = monte_carlo_volume(lat, lat.region(), samples=400_000, seed=3)
        assert abs(cut.volume - est) <= 4 * err and abs(cut.volume / est - 1) < 0.01


@pytest.mark.parametrize("segments", [32, 48])
def test_a_cut_ring_lies_on_the_beams_tangent_cone(segments):
    """The cut ring of a beam between two balls: centred on the axis halfway along the bare part,
    normal to it, on the outer tangent cone of the two balls (radii scaled so that the ring's
    polygon has the exact circle's area), a polygon of the cluster's segments."""
    from ple.meshing.unions import _cut_ring

    c = np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 0.5]])
    rad = np.array([0.3, 0.2])
    ring = _cut_ring(0, c, rad, np.array([[0, 1]]), np.array([0]), 0.0, segments)
    assert len(ring) == segments
    # the n-gon of circumradius s has area n s² sin(2π/n) / 2: π for this s
    scale = np.sqrt(2 * np.pi / (segments * np.sin(2 * np.pi / segments)))
    length = float(np.linalg.norm(c[1]))
    a = c[1] / length
    centre = ring.mean(axis=0)
    assert np.allclose(np.cross(centre, a), 0, atol=1e-12)  # on the axis
    assert np.allclose((ring - centre) @ a, 0, atol=1e-12)  # normal to it
    r1, r2 = rad * scale
    cos_t = (r1 - r2) / length
    p = float(centre @ a)
    # the outer tangent line in a meridian plane, through the two tangent points
    t1 = np.array([r1 * cos_t, r1 * np.sqrt(1 - cos_t**2)])
    t2 = np.array([length + r2 * cos_t, r2 * np.sqrt(1 - cos_t**2)])
    expect = t1[1] + (t2[1] - t1[1]) * (p - t1[0]) / (t2[0] - t1[0])
    assert np.allclose(np.linalg.norm(ring - centre, axis=1), expect)
    assert rad[0] * 1.02 < p < length - rad[1] * 1.02


@pytest.mark.parametrize("seed", range(3))
def test_cut_rings_of_a_turned_beam_are_its_rings_turned_vertex_for_vertex(seed):
    """A cut ring's first vertex is chosen in the frame of the beam's group (``linear``): the ring
    of a beam moved by a rotation R (Rodrigues, a random axis and angle) with its frame given as R
    is R times the ring of the unmoved beam, vertex for vertex; in world axes it is the same
    circle (every vertex on it) but not the same polygon."""
    from ple.algebra.vectors import rotate
    from ple.meshing.unions import _cut_ring

    rng = np.random.default_rng(seed)
    c = np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 0.5]]) + rng.normal(size=3)
    rad = np.array([0.3, 0.2])
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0.3, 2.5)
    rot = rotate(np.eye(3), axis, np.full(3, angle)).T  # columns: the basis vectors turned
    moved = c @ rot.T + rng.normal(size=3)
    bn, beams = np.array([[0, 1]]), np.array([0])
    ring = _cut_ring(0, c, rad, bn, beams, 0.0, 32, lambda rows: np.repeat(np.eye(3)[None], len(rows), 0))
    turned = _cut_ring(0, moved, rad, bn, beams, 0.0, 32, lambda rows: np.repeat(rot[None], len(rows), 0))
    expect = (ring - c[0]) @ rot.T + moved[0]
    assert np.abs(turned - expect).max() < 1e-12
    world = _cut_ring(0, moved, rad, bn, beams, 0.0, 32)
    centre = world.mean(axis=0)
    assert np.allclose(np.linalg.norm(world - centre, axis=1), np.linalg.norm(expect - centre, axis=1))
    assert np.abs(world - expect).max() > 1e-3


def test_copies_along_a_screw_take_kept_pieces(monkeypatch):
    """A thick BCC whose W is a screw (every junction shrunk; the clusters cut across free beams):
    hubs along W are turned copies, their cut rings in their groups' frames, so most pieces are
    kept pieces fitted onto them, not unions (before the rings followed the frames, none were).
    The mesh is closed, oriented, free of self-intersections (exact) and has the volume of the
    mesh made with every piece united anew (to the polygonal balls' turn)."""
    import ple.meshing.tessellate as tessellate_module
    import ple.meshing.unions as unions
    from ple.bench.unclean import case_lattice

    lat = case_lattice("thick_bcc_screw", 6).with_counts(2, 2, 6)
    made = []
    real = tessellate_module.unite_stoppable
    monkeypatch.setattr(tessellate_module, "unite_stoppable", lambda *a: (made.append(1), real(*a))[1])
    whole = tessellate(lat, None, "cnt")
    kept = len(made)
    monkeypatch.setattr(unions.ShapeCache, "get", lambda self, *a: None)
    made.clear()
    plain = tessellate(lat, None, "cnt")
    assert kept < 0.75 * len(made)
    v, f = np.asarray(whole.vertices), np.asarray(whole.faces)
    assert whole.is_watertight and whole.is_winding_consistent and len(self_intersections(v, f)) == 0
    # a kept piece's polygonal balls turn with it, where a fresh union turns all its balls one way:
    # the two polygonal unions differ where balls overlap (6e-5 here), far under a misplaced piece's gap
    assert whole.volume == pytest.approx(plain.volume, rel=5e-4)


@pytest.mark.parametrize("seed", range(4))
def test_rigid_fit_recovers_the_motion_that_made_the_copy(seed):
    """``rigid_fit`` on points moved by a known rotation (from a random axis and angle, Rodrigues)
    and translation gives that motion back; a mirrored solid gets none; flat point sets (a ring)
    get the proper rotation, not the mirror."""
    from ple.meshing.unions import rigid_fit

    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0.01, 3.1)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
    t = rng.normal(size=3) * 10
    p = rng.normal(size=(9, 3))
    got_r, got_t = rigid_fit(p, p @ rot.T + t)
    assert np.allclose(got_r, rot, atol=1e-12) and np.allclose(got_t, t, atol=1e-11)
    assert rigid_fit(p, p * [1, 1, -1])[0] is None
    ring = np.c_[np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4), np.zeros(8)]
    got_r, got_t = rigid_fit(ring, ring @ rot.T + t)
    assert np.linalg.det(got_r) > 0 and np.allclose(ring @ got_r.T + got_t, ring @ rot.T + t, atol=1e-12)


def test_turned_copies_take_a_kept_piece(monkeypatch):
    """On curved rows (V a rotation) the copies of a crossing along U are turned, not moved by
    whole grid steps: they take the kept piece fitted onto them, and many fewer unions are made.
    The pieces carry their own ring floats, the whole mesh is closed, oriented and free of
    self-intersections (exact), and its volume is the fresh unions' mesh's to the grid's size."""
    import ple.meshing.tessellate as tessellate_module
    import ple.meshing.unions as unions

    n = 6
    made = []
    real = unions.ShapeCache.put
    monkeypatch.setattr(unions.ShapeCache, "put", lambda self, *a: (made.append(1), real(self, *a))[1])
    turned = []
    real_moved = unions.ShapeCache._moved
    monkeypatch.setattr(unions.ShapeCache, "_moved",
                        lambda self, *a: (lambda got: (turned.append(got is not None), got)[1])(real_moved(self, *a)))
    whole = tessellate(crossing(n, True), None, "cnt")
    cached = len(made)
    monkeypatch.setattr(unions.ShapeCache, "_moved", lambda self, *a: None)
    made.clear()
    plain = tessellate(crossing(n, True), None, "cnt")
    assert sum(turned) >= (n - 1) * (n - 2) and cached < len(made) / 2
    v, f = np.asarray(whole.vertices), np.asarray(whole.faces)
    assert whole.is_watertight and whole.is_winding_consistent and len(self_intersections(v, f)) == 0
    assert len(whole.faces) == len(plain.faces)
    assert whole.volume == pytest.approx(plain.volume, rel=1e-5)
    assert tessellate_module.ShapeCache is unions.ShapeCache


def test_balls_turned_all_one_way_stay_translates_of_each_other():
    """``TURN_TRIES``: "all" turns every polygonal ball by one turn (each ball minus its centre,
    over its radius, is the same point set, and not the unturned one); "each" turns each ball its
    own way. Every one keeps the exact ball's volume (``unit_ball``) and its vertices on the
    sphere of radius ``cut_bound`` or less."""
    import manifold3d
    from ple.meshing.unions import Cluster, Elements, cut_bound

    c = np.array([[0.0, 0.0, 0.0], [1.0, 0.5, 0.0], [3.0, 1.0, 2.0]])
    rad = np.array([0.2, 0.3, 0.25])
    cl = Cluster(np.arange(3), np.zeros(0, np.int64))
    unit = {t: [(Elements(manifold3d, cl, c, rad, np.zeros((0, 2), np.int64), {}, t).ball(x) - c[x]) / rad[x]
                for x in range(3)] for t in (None, "all", "each")}
    assert all(np.allclose(u, unit["all"][0], atol=1e-12) for u in unit["all"])
    assert not np.allclose(unit["all"][0], unit[None][0])
    assert not np.allclose(unit["each"][1], unit["each"][2])
    for t, balls in unit.items():
        for u in balls:
            hull = manifold3d.Manifold.hull_points(u)
            assert abs(hull.volume() / (4 / 3 * np.pi) - 1) < 1e-9, t
            assert np.linalg.norm(u, axis=1).max() <= cut_bound(cl.segments)


@pytest.mark.parametrize("segments, balls", [(None, 32), (16, 32), (32, 32), (40, 40), (45, 48)])
def test_union_balls_follow_the_meshs_segments(segments, balls, monkeypatch):
    """``unclean.ball_segments``: a union's balls take the mesh's segment count (a multiple of 4,
    at least 32), and the clusters ``tessellate`` unites carry it: each ball of a united cluster
    has the 4·n² + 2 vertices of manifold3d's sphere of s segments (an octahedron whose edges are
    cut in n = s/4)."""
    import manifold3d
    import ple.meshing.tessellate as tessellate_module
    from ple.meshing.unclean import ball_segments
    from ple.meshing.unions import Elements

    assert ball_segments(segments) == balls
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.1)
    for off in [(1, 0, 0), (0, 1, 0), (1, 1, 0), (-1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(3, Translation(Vec(1, 0, 0)))
    lat.set_v(3, Translation(Vec(0, 1, 0)))
    seen = []
    real = tessellate_module.clusters

    def spy(*args):
        got = real(*args)
        seen.extend(got)
        return got

    monkeypatch.setattr(tessellate_module, "clusters", spy)
    mesh = tessellate(lat, style="cnt", segments=segments)
    assert mesh.is_watertight and seen and {c.segments for c in seen} == {ball_segments(segments)}
    ev = lat.evaluate(lat.region())
    ball = Elements(manifold3d, seen[0], ev.center, ev.radius, ev.beam_nodes, {}, None).ball(0)
    assert len(ball) == 4 * (balls // 4) ** 2 + 2
