"""CLG rays, voxels and slices: closed-form cone-beam ray intervals against dense sampling of the
exact distance; first hits against sampled membership and the brute-force value on the surface;
voxels and PNG slices against point membership at the voxel and pixel centres; ``ple slice`` of a
plain lattice against the lattice's PMC."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from ple.algebra.elements import beam_distance
from ple.clg.ir import clg_from_dict
from ple.clg.query import brute_force_value, compiled
from ple.clg.rays import ray_beam_interval, trace
from ple.cli.main import main
from ple.program.sources import load_lattice
from ple.queries.biq import pmc as lattice_pmc

ROOT = Path(__file__).resolve().parents[2]
PRESETS = ROOT / "presets" / "clg"


def test_ray_beam_interval_matches_sampling():
    rng = np.random.default_rng(3)
    n = 400
    ca, cb = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    ra, rb = rng.uniform(0.05, 0.8, n), rng.uniform(0.05, 0.8, n)
    o = rng.normal(size=(n, 3)) * 3
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t0, t1 = ray_beam_interval(o, d, ca, ra, cb, rb)
    ts = np.linspace(-12, 12, 24001)
    for k in range(n):
        f = beam_distance(o[k] + ts[:, None] * d[k], ca[k], ra[k], cb[k], rb[k])
        ins = ts[f <= 0]
        if len(ins) == 0:
            assert np.isnan(t0[k]) or t1[k] - t0[k] < 2e-3
            continue
        assert abs(ins.min() - t0[k]) < 2e-3 and abs(ins.max() - t1[k]) < 2e-3
        # the endpoints are on the surface
        for t in (t0[k], t1[k]):
            assert abs(beam_distance(o[k] + t * d[k], ca[k], ra[k], cb[k], rb[k])) < 1e-9


@pytest.mark.parametrize("name", ["shelled.json", "plate.json", "beam_of_beams.json"])
def test_first_hits(name):
    clg = clg_from_dict(json.loads((PRESETS / name).read_text()))
    comp = compiled(clg)
    rng = np.random.default_rng(1)
    n = 60
    target = comp.lo + rng.random((n, 3)) * (comp.hi - comp.lo)
    o = target + rng.normal(size=(n, 3)) * comp.scale
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = trace(comp, o, d)
    assert np.isfinite(t).sum() >= 5
    ts = np.linspace(0, 1, 3001)
    for k in range(n):
        end = t[k] if np.isfinite(t[k]) else 3 * comp.scale
        pts = o[k] + (ts * end)[:, None] * d[k]
        ins = comp.pmc(pts[:-1])  # nothing inside before the first hit (at this sampling)
        assert not ins.any(), (k, t[k])
        if np.isfinite(t[k]):  # the hit is on the surface, by the brute-force CSG over every copy
            v = brute_force_value(clg, (o[k] + t[k] * d[k])[None])[0]
            assert abs(v) < 1e-6 * comp.scale
            assert comp.pmc((o[k] + (t[k] + 1e-9 * comp.scale) * d[k])[None])[0] or abs(v) < 1e-7


@pytest.mark.parametrize("kind, seed", [("steady", 0), ("becots", 1), ("swirl", 2), ("becots", 3)])
def test_first_hits_on_random_clgs(kind, seed):
    from test_clg_pmc import random_clg
    rng = np.random.default_rng(50 + seed)
    data = random_clg(rng, kind, mat="m" if seed == 3 else None)
    if seed == 3:
        data["materials"] = {"m": {"replace": json.loads((PRESETS / "shelled.json").read_text()), "frame": "world"}}
    clg = clg_from_dict(data)
    comp = compiled(clg)
    n = 40
    target = comp.lo + rng.random((n, 3)) * (comp.hi - comp.lo)
    o = target + rng.normal(size=(n, 3)) * comp.scale
    d = target - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t = trace(comp, o, d)
    ts = np.linspace(0, 1, 2001)
    for k in range(n):
        end = t[k] if np.isfinite(t[k]) else 3 * comp.scale
        assert not comp.pmc(o[k] + (ts[:-1] * end)[:, None] * d[k]).any(), (k, t[k])
        if np.isfinite(t[k]):
            assert abs(brute_force_value(clg, (o[k] + t[k] * d[k])[None])[0]) < 1e-6 * comp.scale


def test_voxelize_cli_matches_pmc_at_centres(tmp_path):
    out = tmp_path / "v.npy"
    src = str(PRESETS / "plate.json")
    assert main(["clg", "voxelize", src, "--grid", "13,9,5", "--bounds", "0,0,-0.3,5,5,1", "--out", str(out)]) == 0
    vox = np.load(out)
    assert vox.shape == (13, 9, 5)
    a, b, c = np.meshgrid(np.arange(13), np.arange(9), np.arange(5), indexing="ij")
    pts = np.stack([0 + (a + 0.5) * 5 / 13, 0 + (b + 0.5) * 5 / 9, -0.3 + (c + 0.5) * 1.3 / 5], -1).reshape(-1, 3)
    comp = compiled(clg_from_dict(json.loads((PRESETS / "plate.json").read_text())))
    assert np.array_equal(vox.reshape(-1), comp.pmc(pts))
    assert 0 < vox.sum() < vox.size


def test_slices_cli(tmp_path):
    from PIL import Image
    src = str(PRESETS / "shelled.json")
    out = tmp_path / "s"
    assert main(["clg", "slice", src, "--layer", "0.5", "--pixel", "0.05", "--out", str(out)]) == 0
    man = json.loads((out / "manifest.json").read_text())
    assert man["format"] == "ple-slices/1" and man["layers"] == len(man["files"]) == 10
    comp = compiled(clg_from_dict(json.loads((PRESETS / "shelled.json").read_text())))
    k = 3
    img = np.array(Image.open(out / man["files"][k]))
    assert Image.open(out / man["files"][k]).mode == "1"
    h, w = img.shape
    lo = comp.lo
    xs = lo[0] + (np.arange(w) + 0.5) * 0.05
    ys = (lo[1] + (np.arange(h) + 0.5) * 0.05)[::-1]
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx.reshape(-1), gy.reshape(-1), np.full(gx.size, man["z"][k])])
    assert np.array_equal(img.reshape(-1).astype(bool), comp.pmc(pts))
    assert man["filled_pixels"][k] == int(img.sum())


def test_plain_lattice_slices(tmp_path):
    out = tmp_path / "p"
    assert main(["slice", "cubic", "--param", "n=3", "--layer", "0.4", "--pixel", "0.04", "--out", str(out)]) == 0
    man = json.loads((out / "manifest.json").read_text())
    from PIL import Image
    img = np.array(Image.open(out / man["files"][1])).astype(bool)
    lat = load_lattice("cubic", ["n=3"])
    lo = np.array(man["origin"])
    h, w = img.shape
    gx, gy = np.meshgrid(lo[0] + (np.arange(w) + 0.5) * 0.04, (lo[1] + (np.arange(h) + 0.5) * 0.04)[::-1])
    pts = np.column_stack([gx.reshape(-1), gy.reshape(-1), np.full(gx.size, man["z"][1])])
    assert np.array_equal(img.reshape(-1), lattice_pmc(lat, pts))


@pytest.mark.parametrize("name", ["shelled.json", "plate.json", "beam_of_beams.json"])
def test_voxelize_by_copies_equals_pmc_per_voxel(name):
    from ple.clg.grid import voxelize, voxelize_clg
    comp = compiled(clg_from_dict(json.loads((PRESETS / name).read_text())))
    lo, hi = comp.lo - 0.05, comp.hi + 0.02
    a = voxelize_clg(comp, lo, hi, (23, 19, 11))
    b = voxelize(comp.pmc, lo, hi, (23, 19, 11))
    assert a.any() and np.array_equal(a, b)
