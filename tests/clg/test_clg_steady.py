"""CLG on steady patterns whose U, V, W do not commute (thesis §5.2; ``ple.clg.steady``): chunk copies
use the lattice's own nodes, found through the RangeFinder of the element lattice. PMC, voxels and
rays on random warped patterns (random rotations, swirls, screws and scalings, random chunk
expressions with union, intersection, difference and compound primitives, recursive materials)
against the independent brute-force CSG of ``clg_reference`` (explicit matrix powers per group);
disagreements only within 1e-7 of a primitive's surface. On commuting patterns the general path
agrees with the similar-copies fast path."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from clg_reference import inside
from ple.clg.grid import voxelize_clg
from ple.clg.ir import clg_from_dict
from ple.clg.query import Compiled, compiled
from ple.clg.rays import trace
from ple.clg.steady import shifted, similar_copies
from ple.cli.main import main
from ple.model.ir import lattice_from_dict
from test_clg_pmc import check, random_clg, random_pattern, sample_points

ROOT = Path(__file__).resolve().parents[2]
SHELLED = json.loads((ROOT / "presets" / "clg" / "shelled.json").read_text())


def near_surface(data, clg, p, scale: float, tol: float = 1e-7) -> np.ndarray:
    """bool (q,): is each point within ``tol`` (relative) of some primitive's surface (brute force)?"""
    dist: list = []
    inside(data, clg, p, dist)
    return np.min(np.array(dist), axis=0) < tol * max(1.0, scale)


def agree(data, clg, p, got, scale) -> None:
    want = inside(data, clg, p)
    bad = got != want
    if bad.any():
        assert near_surface(data, clg, p[bad], scale).all(), f"{int(bad.sum())} points disagree away from surfaces"


@pytest.mark.parametrize("seed", range(8))
def test_pmc_on_non_commuting_patterns_matches_brute_force(seed):
    rng = np.random.default_rng(900 + seed)
    data = random_clg(rng, "warped")
    clg = clg_from_dict(data)
    assert not similar_copies(clg.pattern) and not compiled(clg).similar
    got, want = check(data, 1500, rng)
    assert want.any() or not got.any()


@pytest.mark.parametrize("frame", ["world", "beam"])
def test_recursive_materials_on_non_commuting_patterns(frame):
    rng = np.random.default_rng(31 if frame == "world" else 32)
    data = random_clg(rng, "warped", mat="m")
    inner = random_clg(rng, "warped" if frame == "world" else "steady")
    data["materials"] = {"m": {"replace": inner, "frame": frame}}
    check(data, 600, rng)


@pytest.mark.parametrize("seed", range(3))
def test_voxels_on_non_commuting_patterns_match_brute_force(seed):
    rng = np.random.default_rng(70 + seed)
    data = random_clg(rng, "warped")
    clg = clg_from_dict(data)
    comp = compiled(clg)
    lo, hi = comp.lo - 0.05, comp.hi + 0.03
    shape = (19, 15, 13)
    vox = voxelize_clg(comp, lo, hi, shape)
    a, b, c = np.meshgrid(*(np.arange(n) for n in shape), indexing="ij")
    centres = lo + (np.stack([a, b, c], -1).reshape(-1, 3) + 0.5) * (hi - lo) / shape
    assert np.array_equal(vox.reshape(-1), comp.pmc(centres))  # the same centres, the same sign
    agree(data, clg, centres, vox.reshape(-1), comp.scale)


@pytest.mark.parametrize("seed", range(3))
def test_rays_on_non_commuting_patterns_match_brute_force(seed):
    rng = np.random.default_rng(40 + seed)
    n = 20
    for _ in range(10):  # a random CLG whose solid is not (nearly) empty
        data = random_clg(rng, "warped")
        data["solid"] = {"union": list(data["chunks"])}
        clg = clg_from_dict(data)
        comp = compiled(clg)
        p = sample_points(comp, rng, 2000)
        ins = p[comp.pmc(p)]
        if len(ins) >= n:
            break
    assert len(ins) >= n
    target = ins[rng.choice(len(ins), n, replace=False)]  # rays aimed at points of the solid
    o = target + rng.normal(size=(n, 3)) * comp.scale
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = trace(comp, o, d)
    assert np.isfinite(t).all()  # each ray reaches its target's solid
    ends = t
    ts = np.linspace(0, 1, 251)[:-1]
    before = (o[:, None] + (ts[None, :, None] * ends[:, None, None]) * d[:, None]).reshape(-1, 3)
    ins = inside(data, clg, before)  # nothing inside before the first hits (at this sampling)
    assert not ins.any() or near_surface(data, clg, before[ins], comp.scale).all()
    hit = np.isfinite(t)  # each hit is on some primitive's surface
    assert near_surface(data, clg, o[hit] + t[hit, None] * d[hit], comp.scale, 1e-6).all()


@pytest.mark.parametrize("kind", ["steady", "swirl", "becots"])
def test_general_path_agrees_with_similar_copies(kind):
    """On commuting patterns both paths are valid: the lattice's own nodes give the similar copies'
    PMC and voxels (the fast path unchanged, checked against brute force in test_clg_pmc)."""
    rng = np.random.default_rng(len(kind))
    data = random_clg(rng, kind)
    clg = clg_from_dict(data)
    fast, general = Compiled(clg), Compiled(clg, similar=False)
    assert fast.similar and not general.similar
    p = sample_points(fast, rng, 2000)
    a, b = fast.pmc(p), general.pmc(p)
    if (a != b).any():
        assert near_surface(data, clg, p[a != b], fast.scale).all()
    lo, hi = fast.lo - 0.02, fast.hi + 0.02
    va, vb = voxelize_clg(fast, lo, hi, (16, 12, 9)), voxelize_clg(general, lo, hi, (16, 12, 9))
    assert (va != vb).mean() < 1e-3
    # the general box is the exact box of the positive primitives' balls; the similar copies' box
    # bounds each primitive by one enclosing ball: never smaller
    tol = 1e-9 * fast.scale
    assert np.all(general.lo >= fast.lo - tol) and np.all(general.hi <= fast.hi + tol)


def test_similar_copies_are_refused_on_non_commuting_patterns():
    clg = clg_from_dict(random_clg(np.random.default_rng(3), "warped"))
    with pytest.raises(Exception, match="commuting"):
        Compiled(clg, similar=True)


@pytest.mark.parametrize("seed", range(4))
def test_shifted_lattice_is_the_pattern_reindexed(seed):
    """Node (h, n) of ``shifted(lat, s)`` with template U^s_i ∘ N is the pattern's node (h + s, n)."""
    rng = np.random.default_rng(seed)
    lat = lattice_from_dict(random_pattern(rng, "warped"))
    shift = rng.integers(-3, 3, 3)
    aux, move = shifted(lat, shift, (4, 4, 4))
    for node in lat.nodes:
        c, r = move.apply_balls(node.center, node.radius)
        aux.add_node(c, float(r))
    h = np.column_stack([rng.integers(0, 4, (50, 3)), rng.integers(0, len(lat.nodes), 50)])
    want = lat.node_balls(np.column_stack([h[:, :3] + shift, h[:, 3]]))
    got = aux.node_balls(h)
    scale = float(np.abs(want[0]).max())
    np.testing.assert_allclose(got[0], want[0], atol=1e-10 * scale)
    np.testing.assert_allclose(got[1], want[1], rtol=1e-10)


def test_queries_visit_only_candidate_copies():
    """A point asks the element lattice's RangeFinder, not every copy: on a 10×10×10 warped pattern
    the candidate copies per point are a few, out of a thousand."""
    rng = np.random.default_rng(8)
    pat = random_pattern(rng, "warped")
    for name in "UVW":
        pat[name]["count"] = 10
    data = {"format": "ple-clg/1", "pattern": pat, "solid": "A",
            "chunks": {"A": {"difference": [{"beam": {"from": [0, 0, 0, 0], "to": [1, 0, 0, 0], "scale": [1, 1]}},
                                            {"ball": {"node": [0, 0, 0, 0], "scale": 0.7}}]}}}
    comp = compiled(clg_from_dict(data))
    p = sample_points(comp, rng, 2000)
    idx = comp.near(p, np.zeros(len(p)))
    q, g, c = comp.candidates(p[idx], np.zeros(len(idx)))
    assert len(q) <= 4 * len(p)  # about one copy per point near the solid; the pattern has 1000
    assert comp.pmc(p).any()


def test_region_limits_the_copies():
    """With a region (the add-on's preview) only the region's copies are candidates, and the
    region's solid, a union of chunk copies, holds only points of the whole union."""
    from ple.model.lattice import Region
    rng = np.random.default_rng(12)
    data = random_clg(rng, "warped")
    data["solid"] = {"union": list(data["chunks"])}
    clg = clg_from_dict(data)
    comp = compiled(clg, Region(1, 3, 0, 2, 0, 1))
    p = sample_points(compiled(clg), rng, 800)
    q, g, _ = comp.candidates(p, np.full(len(p), 0.5))
    assert len(q) and np.all((g[:, 0] >= 1) & (g[:, 0] < 3) & (g[:, 1] < 2) & (g[:, 2] == 0))
    assert not (comp.pmc(p) & ~inside(data, clg, p)).any()


def test_cli_on_a_non_commuting_pattern(tmp_path, capsys):
    """Nothing refuses: info, voxels with negative --bounds in the space form, PMC and rays."""
    data = copy.deepcopy(SHELLED)
    data["pattern"]["V"] = {"count": 2, "similarity": {"kind": "rotation", "angle": 0.5, "axis": [1, 0, 0],
                                                       "point": [0, 0, -1.5]}}
    src = tmp_path / "warped.json"
    src.write_text(json.dumps(data))
    assert main(["clg", "info", str(src)]) == 0
    assert json.loads(capsys.readouterr().out)["similar_copies"] is False
    out = tmp_path / "v.npy"
    assert main(["clg", "voxelize", str(src), "--grid", "9,8,7", "--bounds", "-0.5,-0.5,-0.5,1.5,1.5,1.5",
                 "--out", str(out)]) == 0
    vox = np.load(out)
    a, b, c = np.meshgrid(np.arange(9), np.arange(8), np.arange(7), indexing="ij")
    centres = -0.5 + (np.stack([a, b, c], -1).reshape(-1, 3) + 0.5) * 2.0 / np.array([9, 8, 7])
    clg = clg_from_dict(data)
    assert np.array_equal(vox.reshape(-1), compiled(clg).pmc(centres)) and 0 < vox.sum() < vox.size
    pts = tmp_path / "p.npy"
    np.save(pts, centres)
    assert main(["clg", "pmc", str(src), "--points", str(pts), "--out", str(tmp_path / "in.npy")]) == 0
    assert np.array_equal(np.load(tmp_path / "in.npy"), vox.reshape(-1))
    rays = tmp_path / "r.npy"
    np.save(rays, np.array([[-3.0, 0, 0.15, 1, 0, 0], [-3.0, 9, 9, 1, 0, 0]]))  # through a wall; far away
    assert main(["clg", "ray", str(src), "--rays", str(rays), "--out", str(tmp_path / "t.npy")]) == 0
    t = np.load(tmp_path / "t.npy")
    assert np.isfinite(t[0]) and np.isinf(t[1])
