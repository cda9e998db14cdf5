"""Batched hub tessellation (``ple.meshing.hubs.hub_templates``) against the per-hub path.

The batch computes the hubs of one CHoCC topology as arrays; the reference builds every hub
alone (``hub_template``, plane rolling or a validated hint per hub). The meshes must hold the
same triangles (up to the order of their corners and of the faces), be watertight and have
the same volume, and the batch must really batch (fewer per-hub builds than hubs)."""

from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
import trimesh
from ple.meshing import hubs, tessellate
from ple.meshing.tessellate import Tessellator
from ple.model.lattice import Lattice, Node
from ple.program.sources import load_lattice

CURVED = '''
def lattice(n: Range(2, 200) = 6, filtered: bool = False):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.08)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(1, 0, 0)))
    lat.set_v(n, Rotation(0.03, Vec(0, 0, 1), Pt(-30, 0, 0)))
    lat.set_w(n, Swirl(0.02, Vec(0, 1, 0), Pt(50, 0, 0), 0.995))
    if filtered:
        lat.set_filter(ImplicitFilter(TPMSField("gyroid", 7.0, Translation(Vec(-1, -2, -4))), -0.3, "network"))
    return lat
'''


def _mesh(lat, style, batched, levels=1, segments=8):
    r = lat.region()
    if lat.group_map is not None:  # as ``tessellate``: the one-group form of a group-mapped lattice
        lat = lat.explicit(r)
        r = lat.region()
    tess = Tessellator(lat, r, style, levels, segments, batched=batched)
    v, f = tess.build(r)
    return v, f, len(tess.templates)


def _triangles(v, f) -> np.ndarray:
    """Triangles (F, 3, 3) in a canonical order: each starts at its smallest corner (rounded
    lexicographic order, which keeps the orientation), faces sorted."""
    t = v[f]
    key = np.round(t, 6)
    first = np.array([np.lexsort(k.T[::-1])[0] for k in key])
    t = t[np.arange(len(t))[:, None], (first[:, None] + np.arange(3)) % 3]
    return t[np.lexsort(np.round(t.reshape(len(t), -1), 6).T[::-1])]


def _compare(lat, style, monkeypatch, levels=1):
    calls = []
    single = hubs.hub_template

    def counted(*args, **kwargs):
        calls.append(1)
        return single(*args, **kwargs)

    v0, f0, _ = _mesh(lat, style, False, levels)
    monkeypatch.setattr(hubs, "hub_template", counted)
    v1, f1, n_templates = _mesh(lat, style, True, levels)
    monkeypatch.undo()
    assert len(f0) == len(f1)
    assert np.abs(_triangles(v0, f0) - _triangles(v1, f1)).max() < 1e-9
    m0, m1 = trimesh.Trimesh(v0, f0, process=False), trimesh.Trimesh(v1, f1, process=False)
    m0.remove_unreferenced_vertices()
    m1.remove_unreferenced_vertices()
    assert m0.is_watertight and m1.is_watertight
    assert m1.volume == pytest.approx(m0.volume, rel=1e-9)
    return len(calls), n_templates


@pytest.mark.parametrize("style", ["cnt", "chocc", "refined"])
def test_curved_lattice_batches_equal_per_hub(style, tmp_path, monkeypatch):
    path = tmp_path / "curved.py"
    path.write_text(CURVED)
    lat = load_lattice(str(path))
    alone, templates = _compare(lat, style, monkeypatch)
    assert templates > 50 and alone < templates / 3  # most hubs came from batches


def test_filtered_curved_lattice_batches_equal_per_hub(tmp_path, monkeypatch):
    path = tmp_path / "curved.py"
    path.write_text(CURVED)
    lat = load_lattice(str(path), params={"n": 8, "filtered": True})
    assert lat.filter is not None
    alone, templates = _compare(lat, "cnt", monkeypatch)
    assert alone < 0.8 * templates  # filtered: many distinct beam sets, each its own batch


@pytest.mark.parametrize("preset, counts", [
    ("thesis_cylindrical", (3, 8, 3)),
    ("thesis_warped", (5, 5, 4)),
    ("fig6_3", (5, 5, 4)),
    ("spherical_shell", None),
    ("becots_honeycomb", None),
    ("hier_gyroid", None),
    ("rectified_warp", None),
])
def test_presets_batches_equal_per_hub(preset, counts, monkeypatch):
    lat = load_lattice(preset)
    if counts:
        lat = lat.with_counts(*counts)
    elif lat.groups > 300:
        lat = lat.with_counts(*[min(c, 6) for c in lat.counts])
    alone, templates = _compare(lat, "cnt", monkeypatch)
    assert alone <= templates


def test_random_steady_lattices_batch_equal_per_hub(monkeypatch):
    """Random steady lattices: a few nodes, random beams, small random similarities."""
    from ple.algebra.similarity import Rotation, Screw, Translation

    rng = np.random.default_rng(7)
    for trial in range(4):
        lat = Lattice()
        for q in range(2):
            lat.nodes.append(Node(rng.uniform(0, 0.5, 3) * [1, 1, 1] + [0.5 * q, 0, 0], float(rng.uniform(0.05, 0.09))))
        for di, dj, dk in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
            lat.add_beam(0, 0, di, dj, dk)
        lat.add_beam(0, 1, 0, 0, 0)
        lat.add_beam(1, 0, 1, 0, 0)
        lat.add_beam(1, 1, 0, 1, 1)
        lat.set_u(4, Translation((1.5, 0, 0)))
        lat.set_v(4, Rotation(float(rng.uniform(0.02, 0.06)), (0, 0, 1), (-25.0, 0, 0)))
        lat.set_w(3, Screw(float(rng.uniform(0.01, 0.04)), (0, 1, 0), (30.0, 0, 0), 0.0))
        _compare(lat, ["cnt", "refined"][trial % 2], monkeypatch)


def test_stream_is_byte_identical_for_any_number_of_workers(tmp_path, monkeypatch):
    """Boxes are prepared in order and assembled by 1 or 3 threads: the same STL bytes; and
    the same triangles as the in-memory mesh."""
    from ple.app.pipeline import MeshRequest, write_mesh
    from ple.cli.main import main
    from ple.io.export import read_back

    path = tmp_path / "curved.py"
    path.write_text(CURVED)
    lat = load_lattice(str(path), params={"n": 6})
    outs = []
    for workers in (1, 3):
        out = tmp_path / f"w{workers}.stl"
        n = write_mesh(MeshRequest(lat, style="cnt", max_groups=24, workers=workers), out)  # 9 boxes
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    # hub templates in tasks of 5 hub shapes, computed by the template processes (workers > 1)
    monkeypatch.setattr(tessellate, "TEMPLATE_CHUNK", 5)
    tasks = []

    class Counted(ProcessPoolExecutor):
        def submit(self, fn, *args, **kwargs):
            if fn is tessellate._hub_templates_task:
                tasks.append(len(args[0][1]))  # the task's hub shapes
            return super().submit(fn, *args, **kwargs)

    monkeypatch.setattr(tessellate, "ProcessPoolExecutor", Counted)
    for workers in (1, 2):
        out = tmp_path / f"t{workers}.stl"
        write_mesh(MeshRequest(lat, style="refined", levels=1, workers=workers), out)
        outs.append(out.read_bytes())
    assert outs[2] == outs[3]
    assert len(tasks) >= 2 and max(tasks) <= 5  # template tasks of at most 5 hubs ran in the processes
    for workers in (1, 2):
        assert main(["mesh", str(path), "--style", "chocc", "--workers", str(workers),
                     "--out", str(tmp_path / f"cli{workers}.stl")]) == 0
    assert (tmp_path / "cli1.stl").read_bytes() == (tmp_path / "cli2.stl").read_bytes()
    mesh = read_back(tmp_path / "w1.stl")
    assert len(mesh.faces) == n and mesh.is_watertight


def _hub_shapes(h: int, seed: int, w=(0.2466, 0, 0.9691)) -> tuple:
    """H hubs like the unclean ones of the curved bench lattice's boundary (an acute j and
    diagonal beam next to a short W beam in direction ``w``), slowly turning as along a row, the
    W beam from short (its contact circle pulled in from S⁺, or, where ``w`` is near another
    beam, unclean with caps shrunk) to long (clean)."""
    rng = np.random.default_rng(seed)
    base = np.array([[1, 0, 0], [-0.015, 0.9999, 0], w, [0.4514, 0.8923, 0], [-1, 0, 0]])
    t = np.linspace(0, 1, h)[:, None, None]
    d = base[None] + t * rng.normal(0, 0.01, (5, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    length = np.array([1.0, 1.8899, 0.7167, 2.1514, 1.0]) * (1 + t[..., 0] * rng.uniform(-0.05, 0.05, 5))
    length[:, 2] *= np.linspace(0.3, 1.3, h)
    centers = rng.normal(0, 1, (h, 3))
    return centers, np.full(h, 0.08), centers[:, None] + d * length[..., None], np.full((h, 5), 0.08)


def _compare_templates(args, style, levels, min_edge, monkeypatch):
    """hub_templates batched against hub by hub: the same triangles (to 1e-9), r⁺ and clean
    flags; returns (the per-hub templates, the number of per-hub builds of the batched path)."""
    calls = []
    single = hubs.hub_template

    def counted(*a, **k):
        calls.append(1)
        return single(*a, **k)

    ref, _ = hubs.hub_templates(*args, style, levels, 16, min_edge=min_edge, batched=False)
    monkeypatch.setattr(hubs, "hub_template", counted)
    out, _ = hubs.hub_templates(*args, style, levels, 16, min_edge=min_edge)
    monkeypatch.undo()
    for a, b in zip(ref, out):
        assert a.geometry.clean == b.geometry.clean and a.geometry.pulled == b.geometry.pulled
        assert b.geometry.r_plus == pytest.approx(a.geometry.r_plus, rel=1e-12)
        assert np.abs(b.geometry.circle_radii() - a.geometry.circle_radii()).max() < 1e-12
        assert np.abs(b.geometry.alphas - a.geometry.alphas).max() < 1e-12
        fa, fb = np.concatenate([a.faces, *a.caps]), np.concatenate([b.faces, *b.caps])
        assert len(fa) == len(fb)
        assert np.abs(_triangles(a.vertices, fa) - _triangles(b.vertices, fb)).max() < 1e-9
    return ref, len(calls)


@pytest.mark.parametrize("style, levels", [("cnt", 0), ("chocc", 0), ("refined", 2)])
def test_unclean_hubs_batch_equal_per_hub(style, levels, monkeypatch):
    """Junctions with a short beam — its contact circle pulled in from S⁺ (clean), or, where the
    short beam is near another one, unclean (r⁺ capped by ``_max_inflation``, overlapping caps
    shrunk to their share) — are batched like clean ones, with their own flags and circles."""
    from ple.meshing.achocc import contact_circles

    args = _hub_shapes(60, 3, w=(0.8, 0, 0.6))
    ref, alone = _compare_templates(args, style, levels, 0.0, monkeypatch)
    unclean = [t.geometry for t in ref if not t.geometry.clean]
    pulled = [t.geometry for t in ref if t.geometry.pulled]
    shrunk = [g for g in unclean
              if np.any(g.alphas < contact_circles(g.radius, g.r_plus, g.dirs, g.other_radii, g.lengths, False)[0])]
    assert 10 < len(unclean) < len(ref) and len(shrunk) > 5  # both kinds, and caps really shrunk
    assert 10 < len(pulled) and all(g.clean for g in pulled)
    assert alone < len(ref) / 6  # most hubs batched, whatever their kind


@pytest.mark.parametrize("style, levels", [("cnt", 0), ("refined", 2)])
def test_pulled_circles_lie_on_their_beams(style, levels):
    """A pulled-in contact circle is the beam's cone at its ``disk_reach`` (achocc): every ring
    vertex lies on the cone-beam's surface (distance to the axis equals the cone's radius there)
    and within the first MAX_DISK_REACH of the beam, and the cap's centre is on the axis there."""
    from ple.meshing.achocc import MAX_DISK_REACH

    c, r, nb, nr = _hub_shapes(30, 4)
    out, _ = hubs.hub_templates(c, r, nb, nr, style, levels, 16)
    seen = 0
    for h, t in enumerate(out):
        g = t.geometry
        if not g.pulled:
            continue
        for s, ring in enumerate(t.rings):
            d = nb[h, s] - c[h]
            length = np.linalg.norm(d)
            u = d / length
            p = t.vertices[ring] - c[h]
            x = p @ u
            y = np.linalg.norm(p - x[:, None] * u, axis=1)
            # the cone tangent to both balls: radius r at its tangent circle, shrinking by sin(phi) per unit
            sphi = (r[h] - nr[h, s]) / length
            cphi = np.sqrt(1 - sphi**2)
            want = (r[h] - x * sphi) / cphi
            assert np.allclose(y, want, atol=1e-9)
            assert np.ptp(x) < 1e-9 and x[0] < MAX_DISK_REACH * length + 1e-9
            centre = t.vertices[len(t.vertices) - len(t.rings) + s] - c[h]
            assert np.allclose(centre, x[0] * u, atol=1e-9)
            seen += 1
    assert seen > 20


def _canonical_faces(faces) -> list:
    """Faces as sorted tuples, each rotated to start at its smallest id (keeps orientation)."""
    f = np.asarray(faces).reshape(-1, 3)
    f = f[np.arange(len(f))[:, None], (np.argmin(f, axis=1)[:, None] + np.arange(3)) % 3]
    return sorted(map(tuple, f.tolist()))


@pytest.mark.parametrize("tol", [0.004, 0.008, 0.015])
def test_patch_collapse_equals_whole_surface_collapse(tol):
    """``_Surface.collapse`` (the patch around a hub's short edges) gives the faces and rings
    of ``collapse_short_edges`` on the whole surface, on refined hubs whose short edges touch
    each other and need several passes."""
    from ple.meshing.weld import collapse_short_edges

    c, r, nb, nr = _hub_shapes(12, 5)
    several = told = 0
    for h in range(12):
        got: list = []
        hubs.hub_template(c[h], r[h], nb[h], nr[h], "refined", 2, 16, _surface=got)
        faces, rings, _ = got
        verts = hubs._hub_surface(hubs.hub_geometry(r[h], unit := (nb[h] - c[h]) / np.linalg.norm(
            nb[h] - c[h], axis=1)[:, None], nr[h], np.linalg.norm(nb[h] - c[h], axis=1)), "refined", 2, 16)[0]
        assert unit.shape == (5, 3)
        surface = hubs._Surface(faces, rings, len(verts))
        e = surface.edges
        short = np.linalg.norm(verts[e[:, 0]] - verts[e[:, 1]], axis=1) < tol
        f0, r0, n0 = collapse_short_edges(verts, faces, rings, tol)
        local = surface.collapse(verts, short, tol)
        if local is None:  # not local: left to the per-hub path
            continue
        f1, r1, _, _ = local
        assert _canonical_faces(f0) == _canonical_faces(f1)
        assert all(np.array_equal(a, b) for a, b in zip(r0, r1))
        several += collapse_short_edges(verts, faces, rings, tol, rounds=1)[2] < n0
        told += 1
    assert several > 0 and told >= 8  # some hubs took more than one pass; most were told


def test_a_followed_trace_collapses_the_same():
    """``follows_trace``: a mesh whose passes would find the short edges of another's trace in
    the same order collapses to the same faces and rings (checked by collapsing it); one whose
    short edges come in another order does not follow it."""
    from ple.meshing.weld import collapse_short_edges, follows_trace

    c, r, nb, nr = _hub_shapes(6, 5)
    rng = np.random.default_rng(2)
    tol, followed, refused = 0.008, 0, 0
    for h in range(6):
        got: list = []
        hubs.hub_template(c[h], r[h], nb[h], nr[h], "refined", 2, 16, _surface=got)
        faces, rings, _ = got
        unit = (nb[h] - c[h]) / np.linalg.norm(nb[h] - c[h], axis=1)[:, None]
        exact = hubs._hub_surface(hubs.hub_geometry(r[h], unit, nr[h], np.linalg.norm(nb[h] - c[h], axis=1)),
                                  "refined", 2, 16)[0]
        verts = hubs._snapped(exact)  # as the batch collapses: equal lengths stay equal
        trace: list = []
        fa, ra, na = collapse_short_edges(verts, faces, rings, tol, trace=trace)
        if not na:
            continue
        for scale in (1e-9, 1e-6, 1e-4, 3e-3):  # from round-off to moves that reorder or add short edges
            for _ in range(4):
                moved = hubs._snapped(exact + rng.normal(0, scale, verts.shape))
                fb, rb, _ = collapse_short_edges(moved, faces, rings, tol)
                if follows_trace(moved, trace, tol):
                    followed += 1
                    assert np.array_equal(fa, fb)
                    assert all(np.array_equal(x, y) for x, y in zip(ra, rb))
                else:
                    refused += 1
        e, short = trace[0]
        if len(short) > 1:  # the first two short edges swapped: the passes are not the trace's
            swapped = [(e, short[[1, 0, *range(2, len(short))]])] + trace[1:]
            assert not follows_trace(verts, swapped, tol)
    assert followed >= 10 and refused >= 5
    assert not follows_trace(verts, [], tol)  # an empty trace tells nothing


def test_batched_collapses_reuse_traces(monkeypatch):
    """Hubs of a batch whose short edges come in the same order take a traced collapse instead
    of their own (fewer patch collapses than hubs with collapses), with the per-hub triangles:
    shapes in 3 places each (the same hub in its own frame, as along a column) and a small twist
    of each (a neighbouring column)."""
    c, r, nb, nr = _hub_shapes(12, 11)
    rng = np.random.default_rng(4)
    twist = np.array([[1, -1e-7, 0], [1e-7, 1, 0], [0, 0, 1]])
    copies = [(c + off, nb + off[None]) for off in rng.normal(0, 5, (3, 3))]
    copies.append((c, c[:, None] + (nb - c[:, None]) @ twist.T))
    args = (np.concatenate([x for x, _ in copies]), np.tile(r, 4), np.concatenate([y for _, y in copies]),
            np.tile(nr, (4, 1)))
    calls = []
    patch = hubs._Surface.collapse

    def counted(self, *a, **k):
        calls.append(1)
        return patch(self, *a, **k)

    monkeypatch.setattr(hubs._Surface, "collapse", counted)
    ref, alone = _compare_templates(args, "refined", 2, 1e-3, monkeypatch)
    monkeypatch.setattr(hubs._Surface, "collapse", counted)
    calls.clear()
    out, _ = hubs.hub_templates(*args, "refined", 2, 16, min_edge=1e-3)
    plain, _ = hubs.hub_templates(*args, "refined", 2, 16, batched=False)
    collapsed = sum(len(a.faces) < len(b.faces) for a, b in zip(ref, plain))
    assert collapsed > 10 and len(calls) <= collapsed // 2  # each shape collapsed once for its 3 copies, at most


@pytest.mark.parametrize("min_edge", [6.6e-5, 1e-3])
def test_refined_collapses_batch_equal_per_hub(min_edge, monkeypatch):
    """Refined hubs with short edges (clustered, of equal length on symmetric arcs, several
    passes): batched collapses give the per-hub triangles, and almost every hub with collapses
    is batched (both paths collapse on snapped positions, so round-off does not order them)."""
    args = _hub_shapes(40, 11)
    ref, alone = _compare_templates(args, "refined", 2, min_edge, monkeypatch)
    plain, _ = hubs.hub_templates(*args, "refined", 2, 16, batched=False)
    collapsed = sum(len(a.faces) < len(b.faces) for a, b in zip(ref, plain))
    assert collapsed > 10 and alone <= 5


def test_unsure_coordinates_are_those_near_a_snap_boundary():
    """``_unsure`` flags exactly the coordinates that a round-off of SNAP_GUARD can snap to
    another grid point."""
    rng = np.random.default_rng(2)
    base = rng.integers(-2**20, 2**20, (2000, 3)) * hubs.SNAP
    off = rng.uniform(-1, 1, base.shape) * 2 * hubs.SNAP_GUARD
    v = base + 0.5 * hubs.SNAP + off  # near a boundary
    g = rng.uniform(-0.4, 0.4, base.shape) * hubs.SNAP
    w = base + g  # near a grid point
    flip = hubs._snapped(v + hubs.SNAP_GUARD) != hubs._snapped(v - hubs.SNAP_GUARD)
    assert np.array_equal(hubs._unsure(v), np.abs(off) < hubs.SNAP_GUARD)
    assert flip[~hubs._unsure(v)].sum() == 0 and not hubs._unsure(w).any()


@pytest.mark.parametrize("style", ["cnt", "refined"])
def test_template_rounds_do_not_change_the_file(tmp_path, monkeypatch, style):
    """New hub shapes built once per round of boxes (TEMPLATE_ROUND) or box by box: the same
    STL bytes, on 1 and 2 workers."""
    from ple.app.pipeline import MeshRequest, write_mesh

    path = tmp_path / "curved.py"
    path.write_text(CURVED)
    lat = load_lattice(str(path), params={"n": 6})
    outs = []
    for rounds, workers in ((1, 1), (4, 1), (3, 2)):
        monkeypatch.setattr(tessellate, "TEMPLATE_ROUND", rounds)
        out = tmp_path / f"r{rounds}.stl"
        write_mesh(MeshRequest(lat, style=style, levels=1 if style == "refined" else None, max_groups=24,
                               workers=workers), out)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2]


@pytest.mark.parametrize("style, levels", [("cnt", 0), ("refined", 2)])
def test_representatives_carry_to_the_next_call(style, levels, monkeypatch):
    """A second ``hub_templates`` call with the first call's representatives (``reps``, as the
    next round of boxes gets them) batches its hubs on those topologies: fewer per-hub builds
    than without them, and the per-hub triangles either way."""
    c, r, nb, nr = _hub_shapes(60, 3)
    first, second = slice(0, 30), slice(30, 60)
    reps: list = []
    hubs.hub_templates(c[first], r[first], nb[first], nr[first], style, levels, 16, min_edge=1e-3, reps=reps)
    assert 0 < len(reps) <= hubs.REPS_KEPT and all(isinstance(x, hubs.Rep) for x in reps)
    calls = []
    single = hubs.hub_template

    def counted(*a, **k):
        calls.append(1)
        return single(*a, **k)

    monkeypatch.setattr(hubs, "hub_template", counted)
    args = (c[second], r[second], nb[second], nr[second], style, levels, 16)
    carried = list(reps)
    out, _ = hubs.hub_templates(*args, min_edge=1e-3, reps=carried)
    with_reps = len(calls)
    calls.clear()
    hubs.hub_templates(*args, min_edge=1e-3)
    without = len(calls)
    monkeypatch.undo()
    assert with_reps < without
    assert carried and all(isinstance(x, hubs.Rep) for x in carried)
    ref, _ = hubs.hub_templates(*args, min_edge=1e-3, batched=False)
    for a, b in zip(ref, out):
        assert a.geometry.clean == b.geometry.clean
        fa, fb = np.concatenate([a.faces, *a.caps]), np.concatenate([b.faces, *b.caps])
        assert len(fa) == len(fb)
        assert np.abs(_triangles(a.vertices, fa) - _triangles(b.vertices, fb)).max() < 1e-9
    fewer = list(reps)  # representatives of another beam count are not tried
    other, _ = hubs.hub_templates(c[:5], r[:5], nb[:5, :4], nr[:5, :4], style, levels, 16, reps=fewer)
    assert len(other) == 5 and all(x.neighbor_centers.shape == (4, 3) for x in fewer)


def test_one_sided_corridor_samples_equal_both_sided(monkeypatch):
    """``_Batch.corridor_ends`` (only the larger circle of each corridor sampled) gives exactly
    the points of ``chocc.corridor_ends`` (both sides sampled, one kept) on every call of a run
    (a corridor whose larger circle differs between hubs takes ``chocc.corridor_ends`` itself)."""
    from ple.meshing.chocc import corridor_ends

    one_sided = hubs._Batch.corridor_ends
    calls = []

    def checked(self, cor, s):
        got = one_sided(self, cor, s)
        a, b = self.cors[cor, 0], self.cors[cor, 1]
        e1, e2 = self.frames
        want = corridor_ends(self.normals[:, a], self.normals[:, b], self.alphas[:, a], self.alphas[:, b],
                             (e1[:, a], e2[:, a]), (e1[:, b], e2[:, b]), self.th_a0[:, cor], self.da[:, cor],
                             self.th_b0[:, cor], self.db[:, cor], s[None],
                             (self.apexes[0][:, cor], self.apexes[1][:, cor]))
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        calls.append(len(cor))
        return got

    monkeypatch.setattr(hubs._Batch, "corridor_ends", checked)
    args = _hub_shapes(40, 11)
    for style, levels in (("cnt", 0), ("refined", 2)):
        hubs.hub_templates(*args, style, levels, 16, min_edge=1e-3)
    assert len(calls) >= 4 and sum(calls) > 200


def test_template_tasks_are_bounded_and_split_evenly():
    """``_task_bounds``: a beam set's hubs in contiguous tasks of at most TEMPLATE_CHUNK, an even
    number of near-equal ones from TEMPLATE_SPLIT hubs on."""
    for n in [0, 1, 5, tessellate.TEMPLATE_SPLIT - 1, tessellate.TEMPLATE_SPLIT, 456, 767, 768, 769, 2000, 2400]:
        b = tessellate._task_bounds(n)
        assert [lo for lo, _ in b] == [0] * bool(b) + [hi for _, hi in b[:-1]] and (b[-1][1] if b else 0) == n
        sizes = [hi - lo for lo, hi in b]
        assert all(0 < x <= tessellate.TEMPLATE_CHUNK for x in sizes) and (not sizes or max(sizes) - min(sizes) <= 1)
        if n >= tessellate.TEMPLATE_SPLIT:
            assert len(b) % 2 == 0
        elif n:
            assert len(b) == 1
