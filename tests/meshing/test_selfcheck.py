"""The exact self-intersection check (``ple.meshing.selfcheck``) against an independent exact
computation: every pair of faces of random triangle soups (touching, coplanar, sharing edges
and vertices by construction) clipped against each other in rational arithmetic; the compiled
and numpy forms give the same pairs; clean preset meshes have none."""

from __future__ import annotations

from fractions import Fraction
from itertools import combinations

import numpy as np
import pytest
import trimesh
from ple.errors import PleError
from ple.meshing import selfcheck
from ple.meshing.selfcheck import degenerate, orient3d, self_intersections
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

compiled = pytest.mark.skipif(selfcheck._compiled is None, reason="the compiled check is not built")


# ----- the reference: T1 ∩ T2 clipped exactly, then compared with what the faces share -----------

def _sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _lerp(p, q, sp, sq):
    """The point where the segment pq crosses the zero of a linear function with values sp, sq."""
    t = sp / (sp - sq)
    return tuple(x + t * (y - x) for x, y in zip(p, q))


def _clip(points, g):
    """Sutherland–Hodgman: the convex polygon (or segment, or point) ``points`` cut to g ≥ 0."""
    if not points:
        return []
    if len(points) == 1:
        return points if g(points[0]) >= 0 else []
    out = []
    n = len(points)
    for i in range(n if n > 2 else 1):
        p, q = points[i], points[(i + 1) % n]
        sp, sq = g(p), g(q)
        if sp >= 0:
            out.append(p)
        if sp * sq < 0:
            out.append(_lerp(p, q, sp, sq))
        if n == 2 and sq >= 0:
            out.append(q)
    return list(dict.fromkeys(out))


def _intersection(t1, t2):
    """The vertices of T1 ∩ T2 (closed, non-degenerate triangles of Fractions): a list of points
    whose convex hull is the intersection."""
    a, b, c = t1
    n = _cross(_sub(b, a), _sub(c, a))
    s = [_dot(n, _sub(x, a)) for x in t2]
    if all(v == 0 for v in s):
        pts = list(t2)
    else:
        pts = [x for x, v in zip(t2, s) if v == 0]
        for i, j in ((0, 1), (1, 2), (2, 0)):
            if s[i] * s[j] < 0:
                pts.append(_lerp(t2[i], t2[j], s[i], s[j]))
        pts = list(dict.fromkeys(pts))
    for u, w in ((a, b), (b, c), (c, a)):  # T1's edges as half-planes of its plane
        pts = _clip(pts, lambda x, u=u, w=w: _dot(_cross(_sub(w, u), _sub(x, u)), n))
        if not pts:
            break
    return pts


def _on_segment(x, u, w):
    d = _sub(w, u)
    return _cross(d, _sub(x, u)) == (0, 0, 0) and 0 <= _dot(_sub(x, u), d) <= _dot(d, d)


def reference_pairs(vertices, faces) -> set:
    """Every pair of non-degenerate faces whose intersection is more than what they share."""
    v = [tuple(Fraction(float(x)) for x in row) for row in np.asarray(vertices, float)]
    out = set()
    for i, j in combinations(range(len(faces)), 2):
        fa, fb = [int(x) for x in faces[i]], [int(x) for x in faces[j]]
        ta, tb = [v[k] for k in fa], [v[k] for k in fb]
        if any(_cross(_sub(t[1], t[0]), _sub(t[2], t[0])) == (0, 0, 0) for t in (ta, tb)):
            continue
        shared = sorted(set(fa) & set(fb))
        pts = _intersection(ta, tb)
        if len(shared) == 3:
            bad = True
        elif len(shared) == 2:
            bad = any(not _on_segment(x, v[shared[0]], v[shared[1]]) for x in pts)
        elif len(shared) == 1:
            bad = any(x != v[shared[0]] for x in pts)
        else:
            bad = bool(pts)
        if bad:
            out.add((i, j))
    return out


def soup(rng, n_faces: int, grid: int, scale: float = 1.0, offset: float = 0.0):
    """A random soup over a small integer grid (many coplanar, touching and collinear cases),
    faces drawn from a shared vertex pool (shared vertices and edges), without degenerate faces."""
    pool = np.unique(rng.integers(0, grid, size=(3 * n_faces, 3)), axis=0).astype(float) * scale + offset
    faces = []
    while len(faces) < n_faces:
        t = rng.choice(len(pool), 3, replace=False)
        if np.any(np.cross(pool[t[1]] - pool[t[0]], pool[t[2]] - pool[t[0]]) != 0):
            faces.append(t)
    return pool, np.array(faces, np.int64)


def as_set(pairs) -> set:
    return {(int(i), int(j)) for i, j in pairs}


def both_forms(v, f, fresh=None):
    """The compiled form's pairs (when built) and the numpy form's."""
    saved = selfcheck._compiled
    try:
        selfcheck._compiled = None
        numpy_pairs = self_intersections(v, f, fresh)
    finally:
        selfcheck._compiled = saved
    return (self_intersections(v, f, fresh) if saved is not None else numpy_pairs), numpy_pairs


# ----- random soups vs the reference ----------------------------------------------------------

@pytest.mark.parametrize("seed", range(40))
def test_random_soups_match_the_exact_reference(seed):
    rng = np.random.default_rng(seed)
    # integer grids (exact coordinates), and their images under a scale and offset that floats
    # round (near-degenerate configurations that the filters must hand to the exact form)
    scale, offset = [(1.0, 0.0), (0.1, 0.3), (1 / 3, 1e3), (1e-3, -7.7)][seed % 4]
    v, f = soup(rng, 14, 3 + seed % 3, scale, offset)
    ref = reference_pairs(v, f)
    got, numpy_pairs = both_forms(v, f)
    assert as_set(got) == ref
    assert as_set(numpy_pairs) == ref
    assert np.array_equal(got, numpy_pairs)  # the same array, sorted


@pytest.mark.parametrize("seed", range(6))
def test_fresh_faces_keep_exactly_their_pairs(seed):
    rng = np.random.default_rng(100 + seed)
    v, f = soup(rng, 20, 4)
    everything = as_set(self_intersections(v, f))
    fresh = rng.random(len(f)) < 0.3
    want = {(i, j) for i, j in everything if fresh[i] or fresh[j]}
    got, numpy_pairs = both_forms(v, f, fresh)
    assert as_set(got) == want and as_set(numpy_pairs) == want


@pytest.mark.parametrize("seed", range(6))
def test_sides_keep_exactly_the_pairs_across(seed):
    """``sides``: the pairs of the whole soup (every pair tested) whose two faces lie on different
    sides, in both forms; the bucket skip of a one-sided bucket loses none."""
    rng = np.random.default_rng(200 + seed)
    v, f = soup(rng, 20, 4)
    everything = as_set(self_intersections(v, f))
    sides = rng.random(len(f)) < [0.5, 0.1, 0.9][seed % 3]
    want = {(i, j) for i, j in everything if sides[i] != sides[j]}
    assert as_set(self_intersections(v, f, sides=sides)) == want
    saved = selfcheck._compiled
    try:
        selfcheck._compiled = None
        assert as_set(self_intersections(v, f, sides=sides)) == want
    finally:
        selfcheck._compiled = saved
    assert 0 < len(want) < len(everything)


# ----- constructed cases --------------------------------------------------------------------------

Z = [(0.0, 0, 0), (4.0, 0, 0), (0.0, 4, 0)]


@pytest.mark.parametrize("name,second,touching", [
    ("apart", [(0.0, 0, 1), (4.0, 0, 1), (0.0, 4, 1)], False),
    ("piercing", [(1.0, 1, -1), (1.0, 1, 1), (3.0, 3, 0)], True),
    ("vertex on face", [(1.0, 1, 0), (1.0, 1, 3), (2.0, 3, 3)], True),
    ("edge on edge", [(1.0, 0, 0), (3.0, 0, 0), (2.0, -3, 2)], True),
    ("coplanar overlap", [(1.0, 1, 0), (5.0, 1, 0), (1.0, 5, 0)], True),
    ("coplanar touching at a point", [(2.0, 2, 0), (5.0, 2, 0), (2.0, 5, 0)], True),
    ("coplanar apart", [(2.1, 2.1, 0), (5.0, 2.1, 0), (2.1, 5, 0)], False),
    ("coplanar, a hair apart", [(0.0, -1e-300, 0), (4.0, -1e-300, 0), (2.0, -3, 0)], False),
    ("above, a hair apart", [(1.0, 1, 1e-300), (1.0, 1, 3), (2.0, 3, 3)], False),
])
def test_constructed_pairs_without_shared_vertices(name, second, touching):
    v = np.array(Z + second)
    f = np.array([[0, 1, 2], [3, 4, 5]])
    assert len(reference_pairs(v, f)) == touching
    got, numpy_pairs = both_forms(v, f)
    assert len(got) == touching and len(numpy_pairs) == touching, name


@pytest.mark.parametrize("name,far,bad", [
    ("hinge", (2.0, 0, 3), False),
    ("flat, other side", (2.0, -3, 0), False),
    ("flat fold onto itself", (1.0, 1, 0), True),
    ("fold, a hair off the plane", (1.0, 1, 1e-300), False),
])
def test_shared_edge(name, far, bad):
    v = np.array(Z + [far])
    f = np.array([[0, 1, 2], [1, 0, 3]])
    assert len(reference_pairs(v, f)) == bad
    got, numpy_pairs = both_forms(v, f)
    assert len(got) == bad and len(numpy_pairs) == bad, name


@pytest.mark.parametrize("name,others,bad", [
    ("fan", [(-3.0, 0, 1), (-3.0, 3, 2)], False),
    ("through the other", [(1.0, 1, -1), (1.0, 1, 1)], True),
    ("coplanar, overlapping wedges", [(3.0, 1, 0), (1.0, 3, 0)], True),
    ("coplanar, wedges apart", [(-3.0, 1, 0), (-1.0, 3, 0)], False),
    ("along an edge", [(2.0, 0, 0), (1.0, -2, 5)], True),
])
def test_shared_vertex(name, others, bad):
    v = np.array(Z + others)
    f = np.array([[0, 1, 2], [0, 3, 4]])
    assert len(reference_pairs(v, f)) == bad
    got, numpy_pairs = both_forms(v, f)
    assert len(got) == bad and len(numpy_pairs) == bad, name


def test_a_non_finite_corner_is_refused():
    v = np.array(Z + [(1.0, 1, np.nan), (9.0, 9, 9)])
    with pytest.raises(PleError, match="non-finite"):
        self_intersections(v, np.array([[0, 1, 2], [1, 3, 4]]))
    assert len(self_intersections(v, np.array([[0, 1, 2], [0, 1, 4]]))) == 0  # the NaN vertex unused


def test_coincident_faces_and_faces_without_area():
    v = np.array(Z + [(1.0, 1, 0), (2.0, 2, 0), (1.0, 1, -1)])
    # a face, its twin (reversed), a face standing on both, a collinear face, a repeated vertex
    f = np.array([[0, 1, 2], [2, 1, 0], [3, 4, 5], [0, 3, 4], [0, 0, 5]])
    assert degenerate(v, f).tolist() == [False, False, False, True, True]
    got, numpy_pairs = both_forms(v, f)
    assert as_set(got) == as_set(numpy_pairs) == {(0, 1), (0, 2), (1, 2)} == reference_pairs(v, f)


@compiled
def test_expansions_agree_with_integers():
    """The compiled exact orient3d (floating-point expansions) against the numpy form's exact
    integers, on nearly coplanar points of every magnitude."""
    rng = np.random.default_rng(7)
    n = 4000
    a, b, c = (rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-8, 9, (n, 1)) for _ in range(3))
    s, t = rng.random((n, 1)), rng.random((n, 1))
    d = a + s * (b - a) + t * (c - a)  # on the plane up to rounding
    d[::3] += rng.normal(size=(len(d[::3]), 3)) * 1e-12
    got = np.frombuffer(selfcheck._compiled.orient3d_exact(a, b, c, d), np.int8)
    want = selfcheck._exact_orient(a, b, c, d)
    assert np.array_equal(got, want)
    assert np.array_equal(orient3d(a, b, c, d), want)


# ----- meshes ---------------------------------------------------------------------------------------

def test_overlapping_spheres_both_forms():
    s = trimesh.creation.icosphere(3)
    both = trimesh.util.concatenate([s, s.copy().apply_translation([0.5, 0.2, 0.1])])
    got, numpy_pairs = both_forms(both.vertices, both.faces)
    assert len(got) > 0 and np.array_equal(got, numpy_pairs)
    assert np.all((got[:, 0] < len(s.faces)) & (got[:, 1] >= len(s.faces)))  # only across spheres
    for workers in (1, 3):
        assert np.array_equal(self_intersections(both.vertices, both.faces, workers=workers), got)
    apart = trimesh.util.concatenate([s, s.copy().apply_translation([2.0, 0, 0])])  # touching at a point
    got, numpy_pairs = both_forms(apart.vertices, apart.faces)
    assert np.array_equal(got, numpy_pairs)


@compiled
def test_a_huge_face_among_small_ones():
    """One face 10⁶ times the others' size (sliced into cells, the grid coarsened until the faces
    fill few cells): it meets exactly the small faces whose z range holds its plane. (The numpy
    form would slice it into 10⁸ boxes.)"""
    s = trimesh.creation.icosphere(4)
    n = len(s.vertices)
    v = np.vstack([s.vertices, [[-1e6, -1e6, 0.3], [1e6, -1e6, 0.3], [0.0, 1e6, 0.3]]])
    f = np.vstack([s.faces, [[n, n + 1, n + 2]]])
    z = np.asarray(s.vertices)[s.faces][:, :, 2]
    want = {(int(i), len(s.faces)) for i in np.flatnonzero((z.min(axis=1) <= 0.3) & (z.max(axis=1) >= 0.3))}
    assert as_set(self_intersections(v, f)) == want and len(want) > 0


@pytest.mark.parametrize("name,params,style,levels", [
    ("octet", ["n=1"], "refined", 3),
    ("cubic", ["n=2"], "cnt", None),
    ("cubic", ["n=2"], "chocc", None),
])
def test_clean_preset_meshes(name, params, style, levels):
    mesh = tessellate(load_lattice(name, params), style=style, levels=levels)
    got, numpy_pairs = both_forms(mesh.vertices, mesh.faces)
    assert len(got) == 0 and len(numpy_pairs) == 0


# ----- the streamed check of a soup, block by block ---------------------------------------------------

def _soup_of(mesh) -> np.ndarray:
    return np.asarray(mesh.vertices)[np.asarray(mesh.faces)]


@pytest.mark.parametrize("case", ["two spheres", "open", "flipped", "float32"])
def test_blocks_give_the_one_block_report(case):
    """Blocks of a few hundred triangles (a triangle in every block its box meets) count every
    vertex, edge, face and pair once: the report equals the in-memory one and trimesh's."""
    s = trimesh.creation.icosphere(3)
    mesh = trimesh.util.concatenate([s, s.copy().apply_translation([0.5, 0.2, 0.1]),
                                     s.copy().apply_translation([4.0, 0, 0])])
    faces = np.asarray(mesh.faces).copy()
    if case == "open":
        faces = faces[1:]
    if case == "flipped":
        faces[7] = faces[7, ::-1]
    v = np.asarray(mesh.vertices, np.float32 if case == "float32" else float).astype(float)
    ref = trimesh.Trimesh(v, faces, process=False)
    tri = v[faces].astype(np.float32) if case == "float32" else v[faces]
    whole = selfcheck.check_triangles(lambda: iter([tri]))
    for block in (300, 1000):
        split = selfcheck.check_triangles(lambda: (tri[i:i + 500] for i in range(0, len(tri), 500)), block)
        assert split["blocks"] > 1
        assert {k: x for k, x in split.items() if k not in ("blocks", "volume")} == \
               {k: x for k, x in whole.items() if k not in ("blocks", "volume")}
        assert split["volume"] == pytest.approx(whole["volume"], rel=1e-12)
    assert whole["watertight"] == ref.is_watertight
    assert whole["winding_consistent"] == (ref.is_watertight and ref.is_winding_consistent)
    assert whole["euler_characteristic"] == ref.euler_number
    if ref.is_watertight and ref.is_winding_consistent:  # else the volume depends on the origin
        assert whole["volume"] == pytest.approx(ref.volume, rel=1e-12)
    assert whole["self_intersecting_pairs"] == len(self_intersections(v, faces)) > 0


def test_weld_and_faces_without_area_both_forms():
    rng = np.random.default_rng(3)
    tri = rng.integers(-2, 3, size=(400, 3, 3)).astype(float)
    tri[::7] *= -1.0  # −0 beside 0
    vc, fc = selfcheck.weld(tri)
    flat_c = degenerate(vc, fc)
    saved, selfcheck._compiled = selfcheck._compiled, None
    try:
        vn, fn = selfcheck.weld(tri)
        flat_n = degenerate(vn, fn)
    finally:
        selfcheck._compiled = saved
    assert np.array_equal(vc[fc], tri + 0.0) and np.array_equal(vn[fn], tri + 0.0)
    assert len(vc) == len(vn) == len(np.unique(tri.reshape(-1, 3) + 0.0, axis=0))
    assert np.array_equal(flat_c, flat_n)
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert np.array_equal(flat_n, area == 0)


def test_a_streamed_mesh_checked_box_by_box():
    """``iter_triangles``' boxes (hub vertices repeated on box borders, bit-identical) fed to
    ``check_triangles`` without a file: the report of the whole mesh."""
    from ple.meshing.tessellate import iter_triangles  # noqa: PLC0415

    lat = load_lattice("cubic", ["n=6"])
    boxes = list(iter_triangles(lat, style="cnt", max_groups=36))
    assert len(boxes) > 1
    streamed = selfcheck.check_triangles(lambda: (v[f] for v, f in boxes), block=2000)
    mesh = tessellate(lat, style="cnt")
    whole = selfcheck.check_triangles(lambda: iter([np.asarray(mesh.vertices)[np.asarray(mesh.faces)]]))
    assert streamed["blocks"] > 1 and streamed["watertight"] and streamed["winding_consistent"]
    assert {k: x for k, x in streamed.items() if k not in ("blocks", "volume")} == \
           {k: x for k, x in whole.items() if k not in ("blocks", "volume")}
    assert streamed["volume"] == pytest.approx(mesh.volume, rel=1e-9)
