"""Region meshes (001_ §5–6): watertight and consistently oriented for every preset and for
random steady lattices; refined volume against Monte Carlo of the exact union of balls and
cone-beams; projected vertices on the exact boundary; steady copies; streaming."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st
from ple.algebra.similarity import Similarity
from ple.app.pipeline import MeshRequest, write_mesh
from ple.errors import PleError
from ple.meshing.tessellate import Tessellator, tessellate
from ple.model.lattice import Lattice
from ple.program.presets import preset_names
from ple.program.sources import load_lattice

STYLES = [("cnt", None), ("chocc", None), ("refined", 1)]


def small(name, n=2):
    lat = load_lattice(name)
    return lat.with_counts(*[min(c, n) for c in lat.counts])


def assert_closed(mesh, merged=True):
    assert mesh.is_watertight, "mesh has open or non-manifold edges"
    assert mesh.is_winding_consistent
    assert mesh.volume > 0
    if merged:  # also closed once coincident vertices are merged (as readers of STL do)
        m = mesh.copy()
        m.merge_vertices()
        assert m.is_watertight and len(m.faces) == len(mesh.faces)


def assert_closed_unless_filtered_away(lat, mesh, region=None):
    """A program's filter (thesis §9) may keep no node of a small corner: then the mesh is empty."""
    if lat.filter is not None and len(lat.evaluate(region).center) == 0:
        assert len(mesh.faces) == 0
    else:
        assert_closed(mesh)


# ----- independent truth: the union of balls and cone-beams, from 2D geometry ---------------
def beam_frame(p, a, b):
    d = b - a
    length = np.linalg.norm(d)
    q = p - a
    x = q @ (d / length)
    y = np.sqrt(np.maximum(np.einsum("ij,ij->i", q, q) - x * x, 0))
    return x, y, length


def inside_union(p, center, radius, beam_nodes):
    """Membership in the union: a ball, or the band of the cone tangent to both balls between
    its two tangent circles (the 2D hull of two discs)."""
    ins = np.zeros(len(p), bool)
    for c, r in zip(center, radius):
        ins |= np.einsum("ij,ij->i", p - c, p - c) <= r * r
    for i, j in beam_nodes:
        x, y, length = beam_frame(p, center[i], center[j])
        s = (radius[i] - radius[j]) / length
        ins |= (x >= radius[i] * s) & (x <= length + radius[j] * s) & (s * x + np.sqrt(1 - s * s) * y <= radius[i])
    return ins


def monte_carlo_volume(lat, samples=2_000_000, seed=1):
    ev = lat.evaluate()
    lo = (ev.center - ev.radius[:, None]).min(0)
    hi = (ev.center + ev.radius[:, None]).max(0)
    rng = np.random.default_rng(seed)
    hits = 0
    for _ in range(samples // 250_000):
        p = rng.uniform(lo, hi, size=(250_000, 3))
        hits += inside_union(p, ev.center, ev.radius, ev.beam_nodes).sum()
    f = hits / samples
    return f * np.prod(hi - lo), np.prod(hi - lo) * np.sqrt(f * (1 - f) / samples)


def support_distance(p, a, ra, b, rb):
    """Signed distance to hull(ball a, ball b) = max over directions u of u·p − h(u) (exact for
    convex sets), in the 2D plane of p and the axis; dense sampling then golden-section."""
    x, y, length = beam_frame(p, a, b) if np.linalg.norm(b - a) > 0 else (None, None, 0.0)
    if length == 0:
        return np.linalg.norm(p - a, axis=1) - ra

    def f(t):
        return np.cos(t) * x[:, None] + np.sin(t) * y[:, None] - np.maximum(ra, length * np.cos(t) + rb)

    grid = np.linspace(-np.pi, np.pi, 2049)[None]
    best = grid[0, np.argmax(f(grid), axis=1)]
    lo, hi = best - 2 * np.pi / 2048, best + 2 * np.pi / 2048
    g = (np.sqrt(5) - 1) / 2
    for _ in range(80):
        m1, m2 = hi - g * (hi - lo), lo + g * (hi - lo)
        left = f(m1[:, None])[:, 0] > f(m2[:, None])[:, 0]
        hi = np.where(left, m2, hi)
        lo = np.where(left, lo, m1)
    return f(((lo + hi) / 2)[:, None])[:, 0]


def random_steady_lattice(seed):
    rng = np.random.default_rng(seed)

    def step(axis):
        rot = trimesh.transformations.rotation_matrix(rng.uniform(-0.12, 0.12), rng.normal(size=3))
        m = np.eye(4)
        m[:3, :3] = rot[:3, :3] * rng.uniform(0.93, 1.07)
        m[:3, 3] = np.eye(3)[axis] + rng.uniform(-0.1, 0.1, 3)
        return Similarity.from_matrix(m)

    lat = Lattice()
    a = lat.add_node([0, 0, 0], rng.uniform(0.06, 0.14))
    b = lat.add_node(rng.uniform(0.4, 0.6, 3), rng.uniform(0.04, 0.1))
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    for off in [(0, 0, 0), (1, 1, 1), (1, 0, 0)][: rng.integers(1, 4)]:
        lat.add_beam(b, a, *off)
    lat.set_u(2, step(0))
    lat.set_v(2, step(1))
    lat.set_w(int(rng.integers(1, 4)), step(2))
    return lat


# ----- tests ---------------------------------------------------------------------------------
@pytest.mark.parametrize("name", preset_names())
@pytest.mark.parametrize("style,levels", STYLES)
def test_every_preset_is_closed(name, style, levels):
    lat = small(name)
    assert_closed_unless_filtered_away(lat, tessellate(lat, style=style, levels=levels))


@pytest.mark.parametrize("name", preset_names())
def test_region_with_capped_exits_is_closed(name):
    lat = small(name, 3)
    nu, nv, nw = lat.counts
    region = f"0:{max(1, nu - 1)},{min(1, nv - 1)}:{nv},0:{max(1, nw - 1)}"
    full = tessellate(lat, style="cnt")
    part = tessellate(lat, region=region, style="cnt")
    assert_closed_unless_filtered_away(lat, part, region)
    assert part.volume <= full.volume + 1e-9


@pytest.mark.parametrize("name", ["cubic", "octet", "warped", "becots_annulus"])
def test_refined_region_with_capped_exits_is_closed(name):
    lat = small(name, 3)
    nu, nv, nw = lat.counts
    assert_closed(tessellate(lat, region=f"1:{nu},0:{max(1, nv - 1)},0:{nw}", style="refined", levels=1))


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 10**6))
def test_random_steady_lattices_are_closed(seed):
    lat = random_steady_lattice(seed)
    for style, levels in STYLES:
        assert_closed_unless_filtered_away(lat, tessellate(lat, style=style, levels=levels))


@pytest.mark.parametrize("name", ["cubic", "bcc"])
def test_refined_volume_converges_to_exact(name):
    """Default refined is within 1 % of the exact union (Monte Carlo, ±0.2 %), and the error
    falls as levels rise."""
    lat = small(name)
    truth, err = monte_carlo_volume(lat)
    assert err / truth < 0.003
    errors = [abs(tessellate(lat, style="refined", levels=lv).volume / truth - 1) for lv in (1, 2, 3)]
    assert errors[0] > errors[1] > errors[2]
    assert abs(tessellate(lat, style="refined").volume / truth - 1) < 0.01


@pytest.mark.parametrize("name", ["cubic", "bcc", "warped"])
def test_refined_vertices_lie_on_lattice_boundary(name):
    """Every vertex of a whole-lattice refined mesh (projected or snapped onto a contact circle)
    is on the boundary of the union: |signed distance| ≤ 1e-6 of the beam radius."""
    lat = small(name)
    mesh = tessellate(lat, style="refined", levels=2)
    ev = lat.evaluate()
    rng = np.random.default_rng(0)
    v = np.asarray(mesh.vertices)[rng.choice(len(mesh.vertices), 300, replace=False)]
    d = np.full(len(v), np.inf)
    for i, j in ev.beam_nodes:
        d = np.minimum(d, support_distance(v, ev.center[i], ev.radius[i], ev.center[j], ev.radius[j]))
    for c, r in zip(ev.center, ev.radius):
        d = np.minimum(d, np.linalg.norm(v - c, axis=1) - r)
    assert np.max(np.abs(d)) <= 1e-6 * ev.radius.min()


def test_steady_copies_reuse_hub_templates():
    """Hubs are tessellated once per neighbourhood seen from their own frame: for a translation
    lattice once per boundary class (3³), for a curved one once per (i, j, n) and k-class."""
    lat = load_lattice("cubic").with_counts(6, 6, 6)
    t = Tessellator(lat, lat.region(), "cnt", 0, 16)
    mesh = trimesh.Trimesh(*t.build(lat.region()), process=False)
    assert len(t.templates) <= 27
    assert_closed(mesh)
    warped = load_lattice("warped").with_counts(3, 3, 8)
    t = Tessellator(warped, warped.region(), "cnt", 0, 16)
    t.build(warped.region())
    assert len(t.templates) <= 3 * 3 * 3 < warped.groups


def test_stream_matches_in_memory(tmp_path):
    lat = load_lattice("octet").with_counts(3, 3, 2)
    mem = tessellate(lat, style="chocc")
    path = tmp_path / "m.stl"
    n = write_mesh(MeshRequest(lat, style="chocc", max_groups=4), path)  # many boxes, with ghost hubs between them
    assert n == len(mem.faces)
    back = trimesh.load(path)  # merges coincident vertices
    assert back.is_watertight and back.is_winding_consistent
    assert back.volume == pytest.approx(mem.volume, rel=1e-5)


def test_balls_beams_preview_and_bad_input():
    lat = small("cubic")
    assert len(tessellate(lat, style="balls-beams").faces) > 0
    with pytest.raises(PleError, match="style"):
        tessellate(lat, style="voxels")
    with pytest.raises(PleError, match="levels"):
        tessellate(lat, style="refined", levels=9)
    with pytest.raises(PleError, match="region"):
        tessellate(lat, region="0:5,0:1,0:1")


@pytest.mark.parametrize("style", ["cnt", "chocc", "refined"])
def test_placement_similarity_scales_volume(style):
    """Hub meshes live in the template frame: a placement G = rotation ∘ scaling by s moves
    the mesh rigidly and multiplies its volume by s³."""
    from ple.algebra.similarity import Rotation, Scaling
    from ple.algebra.vectors import Pt, Vec

    lat = small("octet")
    base = tessellate(lat, style=style, levels=2)
    lat.set_placement(Rotation(0.7, Vec(1, 2, 3), Pt(1, 0, 0)) @ Scaling(2.5, Pt(0, 1, 0)))
    placed = tessellate(lat, style=style, levels=2)
    assert_closed(placed)
    assert len(placed.faces) == len(base.faces)
    assert placed.volume == pytest.approx(base.volume * 2.5**3, rel=1e-9)


@pytest.mark.parametrize("name", preset_names())
def test_single_group_is_closed(name):
    lat = load_lattice(name).with_counts(1, 1, 1)
    for style, levels in STYLES:
        assert_closed_unless_filtered_away(lat, tessellate(lat, style=style, levels=levels))
