"""Clusters with no free beam, cut into slabs (``ple.meshing.slabs``): a thick lattice whose every
hub is unclean meshes slab by slab into one closed, oriented, self-intersection-free surface with
the volume of the exact union, the streamed file holds the same triangles, and the estimate that
refuses or admits it is the largest slab's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ple.app.pipeline import MeshRequest, write_mesh
from ple.bench.unclean import case_lattice
from ple.cli.main import main
from ple.cli.mesh import monte_carlo_volume
from ple.errors import PleError
from ple.io.export import read_back
from ple.meshing import slabs
from ple.meshing.selfcheck import self_intersections
from ple.meshing.tessellate import Tessellator, tessellate
from ple.meshing.unions import clusters, piece_estimate
from ple.model.lattice import Lattice

manifold3d = pytest.importorskip("manifold3d")
trimesh = pytest.importorskip("trimesh")

OCTET = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0), (1, 0, 1), (-1, 0, 1), (0, 1, 1), (0, -1, 1)]


def thick_octet(n: int = 5) -> Lattice:
    """The bench's thick octet (``ple bench unclean``): the axes and the six face diagonals, r 0.2,
    on rows curved about a far z axis, n × n × max(2, n // 2); every hub is shrunk: one cluster
    with no free beam."""
    return case_lattice("thick_octet", n)


def shrunk_graded(n: int = 4) -> Lattice:
    """The bench's two balls 0.2 apart on each cell, beams shorter than their junctions, graded by
    a scaling U (a step of about 0.5 at the cells): every hub is shrunk."""
    return case_lattice("shrunk_graded", n)


def graded_octet(n: int = 6) -> Lattice:
    """The thick octet graded to thin along U (factor 1 at x = 0, 0.4 at x = 5): its thick end is
    one cluster, which meets the clean thin end along contact rings."""
    from ple.model.grading import LinearGradient

    lat = thick_octet(n).with_counts(n, n, 2)
    lat.radius_field = LinearGradient((0, 0, 0), (5, 0, 0), 1.0, 0.4)
    return lat


def _cluster(lat):
    tess = Tessellator(lat, lat.region(), "cnt", 0, 16)
    report, ev = tess.find_unclean()
    return clusters(report, ev.beam_nodes, ev.center, ev.radius), ev


# the Monte Carlo volume's tolerance: the united balls keep the exact volume, the fast path's
# 16-gon beams (the graded octet's thin clean end) 2.6 % less than their circles' area
@pytest.mark.parametrize("make, within", [(thick_octet, 0.01), (shrunk_graded, 0.01), (graded_octet, 0.04)],
                         ids=["thick_octet", "shrunk_graded", "graded_octet_with_rings"])
def test_a_cluster_without_free_beams_meshes_slab_by_slab(make, within, monkeypatch, tmp_path):
    lat = make()
    cl, _ = _cluster(lat)
    whole = max(piece_estimate(c)[0] for c in cl)  # one cluster holds every hub, or the thick end's
    # the estimate is from above (1,024 triangles a ball, 2,048 a beam); the slabs count the hulls as
    # made (512 and about 270, fewer clipped): a 24th of the estimate is about a quarter of the elements
    limit = whole // 24
    monkeypatch.setattr(slabs, "SLAB_TRIANGLES", limit)
    monkeypatch.setattr(slabs, "SLAB_INPUT", limit)
    mesh = tessellate(lat, None, "cnt", segments=16)
    report = mesh.metadata["ple_unclean"]
    assert report.union_slabs >= 3 and report.united >= 3  # planned slabs, and the unions made (planes may merge)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    check = trimesh.Trimesh(v, f, process=True)  # merged by trimesh itself: closed by coordinates
    assert check.is_watertight and check.is_winding_consistent and check.volume > 0
    assert len(self_intersections(v, f)) == 0
    est, err = monte_carlo_volume(lat, lat.region(), samples=400_000, seed=3)
    assert abs(mesh.volume - est) < within * est + 4 * err
    monkeypatch.setattr(slabs, "SLAB_TRIANGLES", 10 * whole)  # one union: the same solid
    one = tessellate(lat, None, "cnt", segments=16)
    assert one.metadata["ple_unclean"].union_slabs == 1
    assert abs(mesh.volume / one.volume - 1) < 2e-3
    monkeypatch.setattr(slabs, "SLAB_TRIANGLES", limit)  # (SLAB_INPUT is still the limit)
    out = tmp_path / "slabs.stl"
    info: dict = {}
    write_mesh(MeshRequest(lat, style="cnt", segments=16, max_groups=8), out, info=info)
    back = read_back(out)
    assert info["unclean"].union_slabs == report.union_slabs
    assert back.is_watertight and back.is_winding_consistent
    assert abs(back.volume / mesh.volume - 1) < 1e-5


def _without_shifts(monkeypatch):
    """Every slab made (no lattice translation offered to ``slabs._Period``)."""
    from ple.meshing import tessellate as tess_module

    monkeypatch.setattr(tess_module._UnionQueue, "_shifts", lambda self: np.zeros((0, 3)))


@pytest.mark.parametrize("graded", [False, True], ids=["repeating", "graded_middle"])
def test_periods_of_a_translation_are_copied_slabs(graded, monkeypatch):
    """All-shrunk junctions 3 x 12 x 2 repeat along V (a translation): cut along it into slabs
    smaller than a period, one period is united and the later ones are its copies (its pieces
    moved, their seams walked onto their neighbours'). The mesh is closed, oriented and free of
    self-intersections (exact), holds the Monte Carlo volume, and has the triangles and volume of
    the same lattice with every slab united. Graded in its middle (radii change between y = 2 and
    y = 3.5), the copies stop where the balls stop being translates and start again after."""
    from ple.model.grading import LinearGradient

    lat = shrunk_graded().with_counts(3, 12, 2)
    if graded:
        lat.radius_field = LinearGradient((0, 2, 0), (0, 3.5, 0), 1.0, 0.9)
    cl, _ = _cluster(lat)
    limit = max(piece_estimate(c)[0] for c in cl) // 40  # about a third of a period
    monkeypatch.setattr(slabs, "SLAB_TRIANGLES", limit)
    monkeypatch.setattr(slabs, "SLAB_INPUT", limit)
    mesh = tessellate(lat, None, "cnt", segments=16)
    report = mesh.metadata["ple_unclean"]
    assert report.slab_copies >= 3 and report.united >= 3
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    check = trimesh.Trimesh(v, f, process=True)
    assert check.is_watertight and check.is_winding_consistent and check.volume > 0
    assert len(self_intersections(v, f)) == 0
    est, err = monte_carlo_volume(lat, lat.region(), samples=400_000, seed=5)
    assert abs(mesh.volume - est) < 0.01 * est + 4 * err
    _without_shifts(monkeypatch)
    made = tessellate(lat, None, "cnt", segments=16)
    assert made.metadata["ple_unclean"].slab_copies == 0
    assert made.metadata["ple_unclean"].united == report.united + report.slab_copies
    assert len(made.faces) == len(mesh.faces) and abs(made.volume / mesh.volume - 1) < 1e-7


def test_the_estimate_is_the_largest_slab():
    """With a limit of twice the heaviest cross-section (recounted at every element's end), every
    slab of the plan holds about the limit at most and none is empty; the estimate is the largest
    slab's, below the whole cluster's."""
    lat = thick_octet(12)
    cl, ev = _cluster(lat)
    c = cl[0]
    w = slabs.element_triangles(c)
    ext = slabs.element_extents(c, ev.center, ev.radius, ev.beam_nodes)
    axis = int(np.argmax(ext[:, 1].max(axis=0) - ext[:, 0].min(axis=0)))
    lo, hi = ext[:, 0, axis], ext[:, 1, axis]
    heaviest = max(int(w[(lo < x) & (hi > x)].sum()) for x in np.concatenate([lo, hi]))
    limit = 2 * heaviest
    got, cuts = slabs.plan_slabs(w, ext, limit)
    assert got == axis and len(cuts) >= 2 and np.all(np.diff(cuts) > 0)
    edges = [-math.inf, *cuts.tolist(), math.inf]
    loads = [int(w[(hi > a) & (lo < b)].sum()) for a, b in zip(edges[:-1], edges[1:])]
    # elements that start at one plane go to one slab: a slab passes the limit by one such group at most
    group = max(int(w[lo == x].sum()) for x in np.unique(lo))
    assert all(0 < x <= limit + group for x in loads)
    peak, n = slabs.slab_plan_bytes(c, ev.center, ev.radius, ev.beam_nodes, limit)
    assert n == len(cuts) and peak == max(loads) * slabs.UNION_TRIANGLE_BYTES < piece_estimate(c)[1]


def test_slab_load_bounds_the_clipped_hulls_and_the_plane_is_the_farthest():
    """``_SlabContext.clipped`` counts a slab's input from above: for random planes it is at least
    the triangles of the elements' hulls as manifold3d makes them and clips them (and within 2.5x
    of it); ``next_plane`` ends a slab at the farthest position whose count keeps the limit."""
    from ple.meshing.unions import Elements

    cl, ev = _cluster(thick_octet(4))
    c = cl[0]
    make = Elements(manifold3d, c, ev.center, ev.radius, ev.beam_nodes, {}, "all")
    w = slabs.element_triangles(c)
    ext = slabs.element_extents(c, ev.center, ev.radius, ev.beam_nodes)
    axis = 0
    lo, hi = ext[:, 0, axis], ext[:, 1, axis]
    ctx = slabs._SlabContext(make, w, lo, hi, axis, 1e-6, 10.0)
    rng = np.random.default_rng(1)
    for _ in range(6):
        a, b = np.sort(rng.uniform(lo.min(), hi.max(), size=2))
        reach = np.flatnonzero((hi > a) & (lo < b)).tolist()
        bound = sum(ctx.clipped(i, a, b) for i in reach)
        real = 0
        for i in reach:
            h = make.hull(i)
            m = h.to_mesh64()
            v, f = np.asarray(m.vert_properties[:, :3], float), np.asarray(m.tri_verts, np.int64)
            inside = v[:, axis].min() >= a and v[:, axis].max() <= b
            real += h.num_tri() if inside else manifold3d.Manifold.hull_points(slabs._clip(v, f, a, b, axis)).num_tri()
        assert real <= bound <= 2.5 * real
    count = lambda b: sum(ctx.clipped(i, -math.inf, b) for i in np.flatnonzero(lo < b).tolist())  # noqa: E731
    limit = count(math.inf) // 3
    cut = ctx.next_plane(-math.inf, limit, -math.inf)
    assert math.isfinite(cut) and count(cut) <= limit
    later = ctx.ends[ctx.ends > cut + ctx.clear]
    assert len(later) and count(float(later[0])) > limit


def test_strict_hull_drops_collinear_crossings():
    """The 2-D hull's corners are scipy's hull vertices; points on an edge (a cut quad's diagonal
    crossing) are dropped."""
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(4)
    for _ in range(20):
        p = rng.normal(size=(30, 2))
        hull = ConvexHull(p)
        ring = p[hull.vertices]
        mids = 0.5 * (ring + np.roll(ring, -1, axis=0))  # exactly between two corners (up to rounding)
        pts = np.concatenate([p, mids])
        got = slabs._strict_hull(pts)
        assert sorted(got.tolist()) == sorted(hull.vertices.tolist())


def test_a_union_past_the_limit_names_its_hubs_and_pairs(tmp_path, capsys):
    """Refused before it starts, with the largest union's hubs, beams and overlapping pairs."""
    prog = tmp_path / "thick.py"
    prog.write_text(
        "from ple import Lattice, Pt, Vec, Translation, Rotation\n"
        "def lattice():\n"
        "    lat = Lattice()\n"
        "    a = lat.add_node(Pt(0, 0, 0), 0.2)\n"
        f"    for off in {OCTET!r}:\n"
        "        lat.add_beam(a, a, *off)\n"
        "    lat.set_u(5, Translation(Vec(1, 0, 0)))\n"
        "    lat.set_v(5, Rotation(0.06, Vec(0, 0, 1), Pt(-16, 0, 0)))\n"
        "    lat.set_w(2, Translation(Vec(0, 0, 1)))\n"
        "    return lat\n")
    out = tmp_path / "t.stl"
    assert main(["mesh", str(prog), "--style", "cnt", "--max-memory", "60M", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "50 hubs" in err and "overlapping pairs" in err and "local unions" in err
    assert not out.exists()


BALLS_50 = (
    "from ple import Lattice, Pt, Vec, Translation\n"
    "def lattice():\n"
    "    lat = Lattice()\n"
    "    a = lat.add_node(Pt(0, 0, 0), 50)\n"
    "    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:\n"
    "        lat.add_beam(a, a, *off)\n"
    "    for s, v in (('u', Vec(1, 0, 0)), ('v', Vec(0, 1, 0)), ('w', Vec(0, 0, 1))):\n"
    "        getattr(lat, f'set_{s}')(10, Translation(v))\n"
    "    return lat\n")


@pytest.mark.parametrize("door", [("--style", "cnt"), ("--style", "refined"), ("--beam-lattice",)])
def test_a_union_the_balls_foresee_is_refused_before_the_check(tmp_path, capsys, monkeypatch, door):
    """Cubic 10³ whose balls (radius 50, cell 1) all overlap: refused before the unclean check,
    naming its 1,000 hubs, 2,700 beams and C(1000, 2) = 499,500 overlapping balls; the check
    (which would enumerate millions of element pairs) never runs. --beam-lattice's fallback mesh
    is the same pipeline under the same --max-memory (it once ran its unions unestimated)."""
    import ple.app.pipeline as pipeline

    prog = tmp_path / "r50.py"
    prog.write_text(BALLS_50)
    monkeypatch.setattr(pipeline, "checked_stream", lambda *a, **k: pytest.fail("the check ran"))
    out = tmp_path / ("r50.3mf" if door == ("--beam-lattice",) else "r50.stl")
    assert main(["mesh", str(prog), *door, "--max-memory", "1500M", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "foreseen" in err and "1,000 hubs" in err and "2,700 beams" in err and "499,500 overlapping balls" in err
    assert not out.exists()


def test_the_foreseen_union_is_within_the_checks():
    """The balls' foresight is a lower bound: its union's hubs and bytes are at most those of the
    check's largest union (two balls 0.2 apart overlap; the thick octet's balls do not, its hubs
    are unclean by their beams: nothing foreseen); a clean lattice foresees nothing."""
    from ple.meshing.tessellate import foreseen_union, leave_to_unions
    from ple.program.sources import load_lattice

    for lat, overlapping in ((shrunk_graded(), True), (thick_octet(), False)):
        f = foreseen_union(lat)
        assert (f is not None) == overlapping
        if f is not None:
            tess = Tessellator(lat, lat.region(), "cnt", 0, 16)
            report, ev = tess.find_unclean()
            leave_to_unions(tess, ev, report)
            assert 0 < f.hubs <= report.union_hubs and f.bytes <= report.union_bytes
            c, rad = np.asarray(ev.center), np.asarray(ev.radius)  # every pair of balls, brute force
            near = np.linalg.norm(c[:, None] - c[None], axis=2) < rad[:, None] + rad[None]
            assert f.ball_pairs == (near.sum() - len(c)) // 2
    assert foreseen_union(load_lattice("cubic", {"n": 20})) is None


def test_a_request_without_a_limit_is_held_to_the_default(monkeypatch):
    """A door that gives no max_memory (the add-on, batch, a script) is held to the default
    limit (``PLE_MAX_MEMORY``), not left unlimited: the radius-50 cubic is refused before its
    unions, naming them."""
    import ple.app.pipeline as pipeline

    monkeypatch.setenv("PLE_MAX_MEMORY", "1500M")
    monkeypatch.setattr(pipeline, "checked_stream", lambda *a, **k: pytest.fail("the check ran"))
    namespace: dict = {}
    exec(BALLS_50, namespace)
    lat = namespace["lattice"]()
    with pytest.raises(PleError, match="1,000 hubs.*499,500 overlapping balls"):
        pipeline.mesh(pipeline.plan(pipeline.MeshRequest(lat, None, "cnt")))


def test_balls_across_the_whole_cluster_are_not_cut_into_slabs():
    """Where every element reaches across most of the cluster (radius 50 on a unit cell: each
    ball covers all ten cells), the greedy plan does cut, but each of its slabs holds nearly the
    whole union again (``slab_loads``: more than ``SLAB_GAIN`` of it): the estimate keeps one
    union, and so does the mesh (they share ``union_peak``)."""
    from ple.meshing.tessellate import foreseen_union
    from ple.meshing.unions import Cluster

    namespace: dict = {}
    exec(BALLS_50, namespace)
    lat = namespace["lattice"]()
    f = foreseen_union(lat)
    assert (f.hubs, f.ball_pairs, f.slabs) == (1000, 499_500, 1)
    ev = lat.evaluate(lat.region(None))
    bn = np.asarray(ev.beam_nodes, np.int64).reshape(-1, 2)
    whole = Cluster(np.arange(len(ev.center)), np.arange(len(bn)), segments=16)
    w, ext = slabs.element_triangles(whole), slabs.element_extents(whole, ev.center, ev.radius, bn)
    axis, cuts = slabs.plan_slabs(w, ext)
    assert len(cuts) >= 1
    assert min(slabs.slab_loads(w, ext[:, 0, axis], ext[:, 1, axis], cuts)) > slabs.SLAB_GAIN * w.sum()
    assert slabs.union_peak(whole, ev.center, ev.radius, bn)[1] == 1
