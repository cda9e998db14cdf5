"""Möbius steady lattices and TMI maps (thesis §11.3–11.4) through the Lattice's group-map door:
nodes against matrix powers and sphere samples, TMI interpolation and its Trans-Möbius property,
evaluation, queries, measures and meshes (per-hub path) against brute force and Monte Carlo."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ple import Lattice, Pt
from ple.algebra.mobius import Mobius
from ple.errors import PleError
from ple.measure.integrals import lattice_measures
from ple.meshing.tessellate import tessellate
from ple.model.mobius import TMIMap, mobius_frames_lattice, mobius_lattice
from ple.program.sources import load_lattice
from ple.queries import biq

FIVE = (0, 4, 0.5 + 4j, 4.5 + 5j, 2.2 - 0.6j)


def _cell(radius=0.12) -> Lattice:
    cell = Lattice()
    a = cell.add_node(Pt(0, 0, 0), radius)
    cell.add_beam(a, a, 1, 0, 0)
    cell.add_beam(a, a, 0, 1, 0)
    return cell


def _fit(src, dst) -> np.ndarray:
    """Möbius coefficients from 3 correspondences by a null space (independent of ple)."""
    mat = np.stack([src, np.ones(3), -dst * src, -dst], axis=1)
    return np.linalg.svd(mat)[2][-1].conj().reshape(2, 2)


def _apply(m, z):
    return (m[0, 0] * z + m[0, 1]) / (m[1, 0] * z + m[1, 1])


def test_tmi_from_five_interpolates_and_is_trans_mobius():
    tmi = TMIMap.from_five(*FIVE)
    got = tmi(np.array([0, 1, 0, 1, 0.5]), np.array([0, 0, 1, 1, 0]))
    assert np.allclose(got, FIVE, atol=1e-12)
    assert np.allclose((tmi.u @ tmi.v).m, (tmi.v @ tmi.u).m, atol=1e-12)  # U and V commute
    # a translation (0.3, -0.2) of the parameter space is one Möbius transformation of the image
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 1, (12, 2))
    a, b = tmi(uv[:, 0], uv[:, 1]), tmi(uv[:, 0] + 0.3, uv[:, 1] - 0.2)
    m = _fit(a[:3], b[:3])
    assert np.allclose(_apply(m, a[3:]), b[3:], atol=1e-9)


def test_tmi_from_six_interpolates_four_corners():
    pts = (-0.5 - 0.5j, 0, 1j, 2.6 - 0.8j, 3 + 0.2j, 3.2 + 1.5j)
    tmi = TMIMap.from_six(*pts)
    b, c, y, z = pts[1], pts[2], pts[4], pts[5]
    assert np.allclose(tmi(np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])), [b, c, y, z], atol=1e-12)


def test_lattice_nodes_are_exact_mobius_images():
    u = Mobius.from_coefficients(1 + 0.05j, 0.4, 0.03 - 0.02j, 1.0)
    v = Mobius.from_coefficients(1.0, 0.35j, 0.02j, 1 + 0.02j)
    lat = mobius_lattice(_cell(0.1), u, v, None, (6, 5, 1))
    idx = np.array([[0, 0, 0, 0], [3, 2, 0, 0], [5, 4, 0, 0], [1, 4, 0, 0]])
    centers, radii = lat.node_balls(idx)
    rng = np.random.default_rng(1)
    d = rng.normal(size=(64, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    for row, (i, j, _, _) in enumerate(idx):
        m = np.linalg.matrix_power(v.m, j) @ np.linalg.matrix_power(u.m, i)  # repeated composition
        sph = 0.1 * d
        # Poincaré extension written out for the sphere samples (t = height)
        zc, t = sph[:, 0] + 1j * sph[:, 1], sph[:, 2]
        a, b, c, dd = m.ravel()
        den = np.abs(c * zc + dd) ** 2 + np.abs(c) ** 2 * t * t
        zz = ((a * zc + b) * np.conj(c * zc + dd) + a * np.conj(c) * t * t) / den
        img = np.stack([zz.real, zz.imag, t / den], axis=1)
        assert np.allclose(np.linalg.norm(img - centers[row], axis=1), radii[row], atol=1e-12)
    # region evaluation agrees with per-node evaluation
    rc, rr = lat.region_balls()
    c2, r2 = lat.node_balls(lat.region().node_index(1))
    assert np.allclose(rc.reshape(-1, 3), c2) and np.allclose(rr.reshape(-1), r2)
    with pytest.raises(PleError, match="not by similarities"):
        lat.group_matrices([0], [0], [0])


def test_frames_lattice_places_groups_by_frames():
    x = (0j, 1 + 0j, 1j)
    y = (1 + 0j, 2 + 0.1j, 0.9 + 1j)
    z = (1j, 1 + 1.1j, 2j)
    lat = mobius_frames_lattice(_cell(0.05), x, y, z, (3, 3))
    g = lat.group_map
    for (i, j), frame in (((0, 0), x), ((1, 0), y), ((0, 1), z)):
        got = g.map_points(np.full(3, i), np.full(3, j), np.zeros(3), np.array([0, 1, 1j]))
        assert np.allclose(got, frame, atol=1e-12)


def test_queries_measures_and_mesh_of_a_tmi_lattice():
    lat = TMIMap.from_five(*FIVE).lattice(_cell(0.15), (4, 4))
    ev = lat.evaluate()
    assert len(ev.center) == 25 and len(ev.beam_nodes) == lat.beam_count() == 40
    ex = lat.explicit()
    assert np.allclose(ex.template_centers, ev.center) and len(ex.beams) == 40
    # BIQ against brute force on the evaluated balls and beams
    rng = np.random.default_rng(2)
    lo, hi = lat.bounds()
    q = rng.uniform(lo, hi, (40, 3))
    qr = rng.uniform(0, 0.2, 40)
    res = biq.query(lat, q, qr)
    for n, hit in enumerate(res):
        d = np.linalg.norm(ev.center - q[n], axis=1) - ev.radius - qr[n]
        want = set(map(tuple, ev.node_index[d <= 0].tolist()))
        assert set(map(tuple, hit.nodes.tolist())) == want
        assert hit.path.startswith("mobius")  # the pre-image RangeFinder (thesis §11.2.1, §11.4)
    # volume: per-hub measure vs the mesh vs Monte Carlo point membership
    meas = lattice_measures(lat)
    mesh = tessellate(lat, style="refined", levels=3)
    assert mesh.is_watertight
    assert abs(mesh.volume - meas["volume"]) / meas["volume"] < 0.01
    pts = rng.uniform(lo, hi, (60000, 3))
    inside = biq.pmc(lat, pts).mean() * np.prod(hi - lo)
    sigma = np.prod(hi - lo) * np.sqrt(inside / np.prod(hi - lo) / len(pts))
    assert abs(inside - meas["volume"]) < 4 * sigma + 0.005 * meas["volume"]


def test_explicit_is_bounded():
    lat = mobius_lattice(_cell(0.01), Mobius.from_coefficients(1, 0.1, 0.0001, 1), None, None, (1000, 1000, 1))
    with pytest.raises(PleError, match="per-hub path"):
        lat.explicit()


@pytest.mark.parametrize("name", ["tmi_slab", "mobius_slab"])
@pytest.mark.parametrize("style,levels", [("cnt", None), ("chocc", None), ("refined", 1)])
def test_presets_mesh_closed(name, style, levels):
    lat = load_lattice(str(Path(__file__).parents[2] / "presets" / f"{name}.py"), {"nu": 3, "nv": 2})
    mesh = tessellate(lat, style=style, levels=levels)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


def test_tmi_from_five_interpolates_e_for_random_configurations():
    """§11.4.2 warns that angle jumps can break M(.5,0) = E; the branch is chosen so that it holds."""
    rng = np.random.default_rng(3)
    base = np.array([0, 1, 1j, 1 + 1j, 0.5])
    for _ in range(300):
        pts = base + (rng.normal(size=5) + 1j * rng.normal(size=5)) * 0.25
        tmi = TMIMap.from_five(*pts)
        got = tmi(np.array([0, 1, 0, 1, 0.5]), np.array([0, 0, 1, 1, 0]))
        assert np.allclose(got, pts, atol=1e-8)
