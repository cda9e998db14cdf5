"""Unclean lattices: detection of overlapping non-incident elements, and meshes of the union
(manifold3d for the unclean neighbourhoods, the fast path elsewhere) checked against a Monte
Carlo estimate of the union of balls and cone-beams, with the exact self-intersection test."""

from __future__ import annotations

import numpy as np
import pytest
from ple.algebra.similarity import Scaling, Translation
from ple.algebra.vectors import Pt, Vec
from ple.bench.unclean import case_lattice
from ple.cli.mesh import monte_carlo_volume
from ple.meshing.selfcheck import self_intersections
from ple.meshing.tessellate import tessellate
from ple.meshing.unclean import find_unclean
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice
from ple.queries.overlaps import unclean_pairs

manifold3d = pytest.importorskip("manifold3d")


def random_unclean_lattice(seed: int) -> Lattice:
    """Two nodes per cell at random places, thick random radii, beams to random neighbours,
    rows scaled strongly along W: beams cross beams and balls they are not incident to."""
    rng = np.random.default_rng(seed)
    lat = Lattice()
    a = lat.add_node(Pt(*rng.uniform(0, 0.3, 3)), float(rng.uniform(0.12, 0.2)))
    b = lat.add_node(Pt(*(rng.uniform(0.4, 0.7, 3))), float(rng.uniform(0.12, 0.2)))
    lat.add_beam(a, b)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.add_beam(b, a, 1, 1, 0)
    lat.add_beam(b, a, 0, 1, 1)
    lat.set_u(3, Translation(Vec(1, 0, 0)))
    lat.set_v(2, Translation(Vec(0, 1, 0)))
    lat.set_w(3, Scaling(1.25, Pt(0.3, 0.3, -2.0)))
    return lat


def assert_union_mesh(mesh, lat, region=None, samples=600_000, free=True):
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent
    m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=v.astype(np.float32), tri_verts=f.astype(np.uint32)))
    assert m.status() == manifold3d.Error.NoError
    if free:
        assert len(self_intersections(v, f)) == 0
    est, err = monte_carlo_volume(lat, lat.region(region), samples=samples, seed=7)
    assert abs(mesh.volume - est) <= 4 * err
    assert abs(mesh.volume / est - 1) < 0.01


@pytest.mark.parametrize("seed", [1, 2])
def test_random_unclean_lattice_meshes_its_union(seed):
    lat = random_unclean_lattice(seed)
    # the default style (refined, four levels): seed 2 is 0.4 % under the union (three levels: 1 %,
    # five: 0.05 %: the rings' and hubs' polygons, not the unions)
    mesh = tessellate(lat, None, "refined", 4)
    rep = mesh.metadata["ple_unclean"]
    # seed 1 has overlapping balls and beams (``queries.overlaps``, exact): their meshes meet; seed
    # 2's elements are apart, but neighbouring junctions had to shrink
    assert len(rep.nodes) > 0 and (rep.pairs > 0) == (unclean_pairs(lat)["unclean_pairs"] > 0)
    assert rep.pairs > 0 or rep.shrunk_hubs > 0
    assert "united with manifold3d" in rep.line()
    assert_union_mesh(mesh, lat)


@pytest.mark.parametrize("style", ["cnt", "chocc"])
def test_unclean_union_in_every_style(style):
    lat = random_unclean_lattice(1)
    mesh = tessellate(lat, None, style)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert len(self_intersections(v, f)) == 0


def test_thick_octet_meshes_its_union():
    lat = load_lattice("octet", ["n=1", "radius=0.1"])  # about 30 % relative density
    mesh = tessellate(lat, None, "refined")  # default levels: within 1 % of the union
    assert_union_mesh(mesh, lat, free=False)


def test_thick_octet_refined_has_no_self_intersections():
    # was 92 of 23,760 faces: folds at the apexes of point-circle cones (tests/meshing/test_refined_folds.py)
    mesh = tessellate(load_lattice("octet", ["n=2", "radius=0.1"]), None, "refined", 2)
    assert len(self_intersections(mesh.vertices, mesh.faces)) == 0


def test_clean_lattice_keeps_the_fast_path():
    lat = load_lattice("bcc").with_counts(2, 2, 2)
    mesh = tessellate(lat, None, "cnt")
    assert len(mesh.metadata["ple_unclean"].nodes) == 0
    fast = tessellate(lat, None, "cnt", check_clean=False)
    assert np.array_equal(mesh.faces, fast.faces) and np.array_equal(mesh.vertices, fast.vertices)


def test_detection_of_parallel_beams():
    # two parallel beams 0.5 apart, no common ball: unclean at radius 0.3, clean at 0.2
    c = np.array([[0, 0, 0], [3, 0, 0], [0, 0.5, 0], [3, 0.5, 0.0]])
    beams = np.array([[0, 1], [2, 3]])
    for r, unclean in ((0.3, True), (0.2, False)):
        rep = find_unclean(c, np.full(4, r), beams, np.full(4, r))
        assert (len(rep.nodes) == 4) == unclean and (rep.pairs > 0) == unclean
    # a ball sitting on a beam it is not joined to
    c2 = np.array([[0, 0, 0], [3, 0, 0], [1.5, 0.15, 0.0]])  # 0.15 < 0.1 + 0.1
    rep = find_unclean(c2, np.full(3, 0.1), np.array([[0, 1]]), np.full(3, 0.1))
    assert set(rep.nodes.tolist()) == {0, 1, 2}


@pytest.mark.parametrize("seed", [1, 3])
def test_detection_equals_all_pairs_of_capsules(seed):
    """The tessellation's unclean hubs (candidates from ``queries.overlaps.non_incident_pairs``)
    equal a test of every pair of elements: hub spheres S⁺ and trimmed beam capsules."""
    from ple.algebra.elements import segment_distance
    from ple.meshing.unclean import TRIM

    ev = random_unclean_lattice(seed).evaluate()
    c, r, bn = ev.center, ev.radius, ev.beam_nodes
    rp = 1.3 * r
    rep = find_unclean(c, r, bn, rp)
    n = len(c)
    a, b = c[bn[:, 0]], c[bn[:, 1]]
    u = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
    trim = TRIM * np.sqrt(rp**2 - r**2)
    seg0 = np.concatenate([c, a + u * trim[bn[:, 0], None]])
    seg1 = np.concatenate([c, b - u * trim[bn[:, 1], None]])
    rr = np.concatenate([rp, np.maximum(r[bn[:, 0]], r[bn[:, 1]])])
    ends = [{x} for x in range(n)] + [set(e) for e in bn.tolist()]
    edges = {frozenset(e) for e in bn.tolist()}
    bad, pairs = set(), 0
    for i in range(len(ends)):
        for j in range(i + 1, len(ends)):
            if ends[i] & ends[j] or (i < n and j < n and frozenset((i, j)) in edges):
                continue
            if segment_distance(seg0[i], seg1[i], seg0[j], seg1[j]) < rr[i] + rr[j]:
                pairs += 1
                bad |= ends[i] | ends[j]
    assert rep.pairs == pairs > 0 and set(rep.nodes.tolist()) == bad


def steady_lattice(seed: int) -> Lattice:
    """Like ``random_unclean_lattice``, with 12 layers along W (a rotation or a shrinking scaling)."""
    from ple.algebra.similarity import Rotation

    lat = random_unclean_lattice(seed)
    w = Rotation(0.5, Vec(0, 0, 1), Pt(0.5, 0.5, 0)) if seed % 2 else Scaling(0.93, Pt(0.3, 0.3, -2.0))
    lat.set_w(12, w)
    return lat


def _spheres(tess):
    ev = tess.lat.evaluate(tess.region)
    idx = np.asarray(ev.node_index, np.int64)
    tids, _, _, _ = tess.instances(idx)
    rp = np.array([t.geometry.r_plus for t, _ in tess.tpl_list])[tids] * tess.lat.group_factors(*idx[:, :3].T)
    return ev, idx, rp


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_steady_check_equals_the_search_of_every_element(seed, monkeypatch):
    """Anchored layers and their copies along W (``steady``) find exactly the unclean hubs and the
    pairs of the search over every element, looked up in one block or in many; with the meshes'
    hulls, at least its hubs."""
    from ple.meshing import unclean
    from ple.meshing.tessellate import Tessellator

    lat = steady_lattice(seed)
    tess = Tessellator(lat, lat.region(), "cnt", 0, 16)
    ev, idx, rp = _spheres(tess)
    steady = tess._steady_layers(idx)
    assert steady is not None and steady[1:3] == (1, 11)
    whole = find_unclean(ev.center, ev.radius, ev.beam_nodes, rp)
    layered = find_unclean(ev.center, ev.radius, ev.beam_nodes, rp, steady=steady)
    assert whole.pairs > 100 and layered.pairs == whole.pairs
    assert np.array_equal(layered.nodes, whole.nodes)
    monkeypatch.setattr(unclean, "QUERY_BLOCK", 37)  # the others looked up 37 at a time
    blocks = find_unclean(ev.center, ev.radius, ev.beam_nodes, rp, steady=steady)
    assert blocks.pairs == whole.pairs and np.array_equal(blocks.nodes, whole.nodes)
    monkeypatch.undo()
    report, _ = tess.find_unclean()  # steady, with the hulls
    plain = Tessellator(lat, lat.region(), "cnt", 0, 16)
    plain._steady_layers = lambda idx: None
    alone, _ = plain.find_unclean()
    assert set(alone.nodes.tolist()) <= set(report.nodes.tolist())


def _hull_distance(a, b):
    """Distance between the convex hulls of two small point sets: a quadratic program over convex
    weights (scipy SLSQP), independent of ``separated``."""
    from scipy.optimize import minimize

    na = len(a)

    def gap(w):  # squared distance of the two convex combinations, and its gradient
        d = w[:na] @ a - w[na:] @ b
        return d @ d, np.concatenate([2 * a @ d, -2 * b @ d])

    in_a = np.concatenate([np.ones(na), np.zeros(len(b))])
    cons = [{"type": "eq", "fun": lambda w: w[:na].sum() - 1, "jac": lambda w: in_a},
            {"type": "eq", "fun": lambda w: w[na:].sum() - 1, "jac": lambda w: 1 - in_a}]
    w0 = np.concatenate([np.full(na, 1 / na), np.full(len(b), 1 / len(b))])
    res = minimize(gap, w0, jac=True, method="SLSQP", bounds=[(0, 1)] * len(w0), constraints=cons,
                   options={"ftol": 1e-14, "maxiter": 500})
    return float(np.sqrt(max(res.fun, 0.0)))


def test_separated_is_a_proof_and_finds_clear_gaps():
    from ple.meshing.unclean import separated

    rng = np.random.default_rng(4)
    k = 150
    a = rng.normal(size=(k, 12, 3)) * rng.uniform(0.2, 1.5, (k, 1, 3))
    b = rng.normal(size=(k, 10, 3)) * rng.uniform(0.2, 1.5, (k, 1, 3)) + rng.normal(size=(k, 1, 3)) * 2.5
    margin = 0.05
    got = separated(a, b, margin)
    dist = np.array([_hull_distance(a[i], b[i]) for i in range(k)])
    assert 20 < got.sum() < k - 20  # both cases occur
    assert np.all(dist[got] > margin - 1e-6)  # a proof: hulls claimed apart are apart
    assert np.all(got[dist > 3 * margin])  # and clear gaps are found
    assert not separated(a, a + 1e-3, 0.0).any()  # overlapping hulls never are


def test_false_alarms_of_the_spheres_leave_the_fast_mesh():
    """The warped preset at n = 12: its short, thick bent-end beams made the junction spheres
    overlap non-neighbours; the elements are apart (``queries.overlaps``, exact), the meshes'
    hulls too, and the fast mesh has no self-intersection (exact test) and is closed."""
    lat = load_lattice("warped", {"n": 12})
    assert unclean_pairs(lat)["unclean_pairs"] == 0
    mesh = tessellate(lat, None, "cnt")
    assert len(mesh.metadata["ple_unclean"].nodes) == 0
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert len(self_intersections(mesh.vertices, mesh.faces)) == 0


def short_beam_lattice(n: int = 4) -> Lattice:
    """A curved lattice whose W-beams (about 0.42) are shorter than the reach of its junctions'
    S⁺ (set by the acute U and diagonal beams): every hub's W circles are pulled in from S⁺ (the
    bench's ``curved`` case)."""
    return case_lattice("curved", n)


@pytest.mark.parametrize("style, levels, tol", [("refined", 3, 0.01), ("cnt", 0, 0.05)])
def test_short_beams_mesh_without_unions(style, levels, tol):
    """Junctions beside short beams keep their contact circles on the beams (pulled in from S⁺):
    no hub is unclean, the mesh is closed and free of self-intersections (exact check), and its
    volume is the union's (Monte Carlo of balls and cone-beams, independent of the mesher)."""
    lat = short_beam_lattice()
    mesh = tessellate(lat, None, style, levels)
    rep = mesh.metadata["ple_unclean"]
    assert len(rep.nodes) == 0 and rep.shrunk_hubs == 0
    pulled = [t.geometry.pulled for t in _templates(lat, style, levels)]
    assert sum(pulled) > 10
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent and len(self_intersections(v, f)) == 0
    est, err = monte_carlo_volume(lat, lat.region(), samples=400_000, seed=3)
    assert abs(mesh.volume / est - 1) < tol + 4 * err / est  # cnt: flat faces between the circles


def _templates(lat, style, levels):
    from ple.meshing.tessellate import Tessellator

    tess = Tessellator(lat, lat.region(), style, levels, 16)
    tess.instances(lat.region().node_index(len(lat.nodes)))
    return [t for t, _ in tess.tpl_list]


@pytest.mark.parametrize("style", ["cnt", "chocc"])
def test_neighbouring_pulled_hubs_apart_by_their_meshes(style, monkeypatch):
    """Far rows of the curved 40³ (W-beams about 0.33): neighbouring pulled junctions whose hulls
    overlap (no separating plane: ``separated`` finds none) while their meshes do not meet. The
    hubs stay on the fast path, and the region's mesh is closed and free of self-intersections
    (exact). (Its volume is not the region's union: beams leaving a region end in capped stubs; the
    whole curved lattice's volume is tested above.)"""
    import ple.meshing.unclean as unclean
    from ple.model.lattice import Region

    lat, region = case_lattice("curved", 40), Region(32, 36, 10, 14, 10, 14)
    seen = {}
    hulls_only = unclean._pulled_neighbours

    def spy(pulled, bn, points, margin, meet=None, steady=None, farther=None):
        seen["hulls"] = len(hulls_only(pulled, bn, points, margin))
        seen["meshes"] = len(hulls_only(pulled, bn, points, margin, meet))
        return hulls_only(pulled, bn, points, margin, meet, steady, farther)

    monkeypatch.setattr(unclean, "_pulled_neighbours", spy)
    mesh = tessellate(lat, region, style)
    assert seen["hulls"] > 20 and seen["meshes"] == 0  # the hulls alone would have sent them to unions
    assert len(mesh.metadata["ple_unclean"].nodes) == 0
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert mesh.is_watertight and mesh.is_winding_consistent and len(self_intersections(v, f)) == 0


def test_hubs_meet_sees_a_hub_meet_itself():
    """``_hubs_meet`` answers True for a hub paired with itself (every face meets its copy) and
    False for neighbours of a clean lattice, so it is not vacuous."""
    from ple.meshing.tessellate import Tessellator

    lat = short_beam_lattice(4)
    tess = Tessellator(lat, lat.region(), "cnt", 0, 16, grid=2.0**-20)
    ev = lat.evaluate(lat.region())
    tids, m, _, _ = tess.instances(np.asarray(ev.node_index, np.int64))
    hubs = np.arange(len(tids))
    assert tess._hubs_meet(tids, m, np.stack([hubs, hubs], 1)).all()
    assert not tess._hubs_meet(tids, m, np.asarray(ev.beam_nodes, np.int64)).any()


def test_hubs_meet_in_a_batch_as_pair_by_pair():
    """``_hubs_meet`` tests many pairs in one exact check; each answer equals that of the pair
    alone (its two hubs placed and rounded to the grid, every face against every face)."""
    from ple.meshing.tessellate import Tessellator

    lat = short_beam_lattice(4)
    tess = Tessellator(lat, lat.region(), "cnt", 0, 16, grid=2.0**-20)
    ev = lat.evaluate(lat.region())
    tids, m, _, _ = tess.instances(np.asarray(ev.node_index, np.int64))
    rng = np.random.default_rng(3)
    hubs = rng.integers(0, len(tids), 40)
    pairs = np.concatenate([np.stack([hubs, hubs], 1), np.asarray(ev.beam_nodes, np.int64)[:60],
                            rng.integers(0, len(tids), (40, 2))])
    pairs = pairs[rng.permutation(len(pairs))]
    batch = tess._hubs_meet(tids, m, pairs, chunk=32)

    def alone(a, b):
        v, f = [], []
        for h in (a, b):
            tpl = tess.tpl_list[int(tids[h])][0]
            f.append(np.asarray(tpl.faces, np.int64) + sum(len(x) for x in v))
            v.append(np.round((tpl.vertices @ m[h, :3, :3].T + m[h, :3, 3]) / tess.grid))
        owner = np.repeat([0, 1], [len(f[0]), len(f[1])])
        hits = self_intersections(np.concatenate(v), np.concatenate(f))
        return bool((owner[hits[:, 0]] != owner[hits[:, 1]]).any())

    assert batch.tolist() == [alone(a, b) for a, b in pairs.tolist()]
    assert batch.any() and not batch.all()


def test_steady_anchors_prove_their_copies_apart(monkeypatch):
    """On a curved region with steady layers, neighbouring pulled junctions are tested in the
    anchor layer only: the junctions still sent to unions are a subset of those the pair-by-pair
    test sends, and the pairs only the anchors proved apart do not meet (their meshes, exact)."""
    import ple.meshing.unclean as unclean
    from ple.meshing.tessellate import Tessellator
    from ple.model.lattice import Region

    lat, region = case_lattice("curved", 40), Region(30, 33, 8, 11, 0, 12)
    seen = {}
    pulled_neighbours = unclean._pulled_neighbours

    def spy(pulled, bn, points, margin, meet=None, steady=None, farther=None):
        assert steady is not None
        seen["steady"] = pulled_neighbours(pulled, bn, points, margin, None, steady)
        seen["alone"] = pulled_neighbours(pulled, bn, points, margin, None, None)
        return seen["steady"]

    monkeypatch.setattr(unclean, "_pulled_neighbours", spy)
    tess = Tessellator(lat, region, "cnt", 0, 16)
    tess.find_unclean()
    key = lambda p: set(map(tuple, np.asarray(p).tolist()))  # noqa: E731
    assert len(seen["alone"]) > 20 and key(seen["steady"]) <= key(seen["alone"])
    only = np.array(sorted(key(seen["alone"]) - key(seen["steady"])), np.int64).reshape(-1, 2)
    ev = lat.evaluate(region)
    tids, m, _, _ = tess.instances(np.asarray(ev.node_index, np.int64))
    assert not tess._hubs_meet(tids, m, only).any()


def test_anchor_meshes_farther_apart_free_their_copies(monkeypatch):
    """Copies of anchor pairs whose placed meshes are proven farther apart than the margin over
    the layers' shrink (``Tessellator._hubs_farther``) skip the mesh test: the pulled pairs found
    are those found when every copy is tested on its meshes (exact), with far fewer tests."""
    import ple.meshing.unclean as unclean
    from ple.meshing.tessellate import Tessellator
    from ple.model.lattice import Region

    lat, region = case_lattice("curved", 40), Region(30, 33, 8, 11, 0, 12)
    found, tested = {}, {}
    pulled_neighbours = unclean._pulled_neighbours

    def spy(pulled, bn, points, margin, meet=None, steady=None, farther=None):
        assert steady is not None and meet is not None and farther is not None
        for name, far in (("farther", farther), ("meshes", None)):
            tested[name] = 0

            def counted(p, name=name):
                tested[name] += len(p)
                return meet(p)

            found[name] = pulled_neighbours(pulled, bn, points, margin, counted, steady, far)
        return found["farther"]

    monkeypatch.setattr(unclean, "_pulled_neighbours", spy)
    Tessellator(lat, region, "cnt", 0, 16).find_unclean()
    key = lambda p: set(map(tuple, np.asarray(p).tolist()))  # noqa: E731
    assert key(found["farther"]) == key(found["meshes"])
    assert tested["meshes"] > 50 and tested["farther"] < tested["meshes"] / 2, tested


@pytest.mark.parametrize("seed", range(2))
def test_triangles_proven_apart_are_apart(seed):
    """``_triangles_within``: a pair it proves more than gap apart is (densely sampled points of
    both triangles, whose nearest pair is at least the distance); and it proves most pairs that
    are clearly farther (twice the gap and the sampling's resolution)."""
    from ple.meshing.tessellate import _triangles_within

    rng = np.random.default_rng(seed)
    k = 200
    t1 = rng.normal(size=(k, 3, 3))
    t2 = rng.normal(size=(k, 3, 3)) + rng.normal(size=(k, 1, 3)) * 2
    gap = 0.3
    within = _triangles_within(t1, t2, gap)
    u, v = np.meshgrid(np.linspace(0, 1, 25), np.linspace(0, 1, 25))
    keep = u + v <= 1
    bary = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], axis=1)  # (S, 3)
    p1, p2 = np.einsum("sc,kci->ksi", bary, t1), np.einsum("sc,kci->ksi", bary, t2)
    sampled = np.array([np.sqrt(np.min(np.einsum("si,si->s", a, a)[:, None] + np.einsum("ti,ti->t", b, b)[None]
                                       - 2 * a @ b.T).clip(0)) for a, b in zip(p1, p2)])
    both = np.concatenate([t1, t2], axis=1)
    edge = np.linalg.norm(both[:, [1, 2, 0, 4, 5, 3]] - both, axis=2).max(axis=1) / 24  # sampling resolution
    assert (sampled[~within] > gap).all()
    clear = sampled > 2 * gap + 2 * edge
    assert clear.sum() > 30 and within[clear].mean() < 0.5
