"""Implicit fields: TPMS formulas, FFT Fourier fits (004_ §3.2), T_d symmetrization, implicit filters."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from ple.algebra.similarity import Rotation, Swirl
from ple.cli.common import parse_implicit
from ple.errors import PleError
from ple.filters.base import FilteredLattice
from ple.filters.implicit import TD_OPERATORS, FourierField, ImplicitFilter, TPMSField, sample_grid
from ple.io.files import save_npz
from ple.program.sources import load_lattice


def gyroid(p):
    x, y, z = (2 * math.pi * p).T
    return np.sin(x) * np.cos(y) + np.sin(y) * np.cos(z) + np.sin(z) * np.cos(x)


def random_band_limited(rng, h: int):
    """A random real field with integer frequencies |f_i| <= h (Hermitian pairs built explicitly)."""
    f = rng.integers(-h, h + 1, size=(12, 3))
    a, b = rng.normal(size=12), rng.normal(size=12)
    return lambda p: (np.cos(2 * math.pi * p @ f.T) @ a + np.sin(2 * math.pi * p @ f.T) @ b)


def test_td_has_24_distinct_orthogonal_operators_forming_a_group():
    ops = TD_OPERATORS
    assert len({q.tobytes() for q in ops}) == 24
    for q in ops:
        assert np.allclose(q @ q.T, np.eye(3))
    keys = {q.astype(int).tobytes() for q in ops}
    for a in ops:
        for b in ops:
            assert (a @ b).astype(int).tobytes() in keys
    # the tetrahedron's vertices are permuted by every operator
    verts = {tuple(v) for v in [(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)]}
    for q in ops:
        assert {tuple((q @ np.array(v)).astype(int)) for v in verts} == verts


def test_fourier_fit_reproduces_band_limited_gyroid():
    x = np.random.default_rng(0).uniform(-3, 3, (2000, 3))
    for n in (4, 8, 16):  # Nyquist (004_ §3.2): the gyroid's highest frequency 1 < N/2
        fit = FourierField.fit(sample_grid(gyroid, n), symmetric=False)
        assert np.abs(fit(x) - gyroid(x)).max() < 1e-6
    assert len(FourierField.fit(sample_grid(gyroid, 16), symmetric=False).freqs) == 12


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_of_random_band_limited_field(seed):
    rng = np.random.default_rng(seed)
    g = random_band_limited(rng, 3)
    x = rng.uniform(-2, 2, (1000, 3))
    fit = FourierField.fit(sample_grid(g, 8), symmetric=False)
    assert np.abs(fit(x) - g(x)).max() < 1e-6


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_symmetrized_fit_is_the_td_average_and_invariant(seed):
    rng = np.random.default_rng(seed)
    g = random_band_limited(rng, 3)
    x = rng.uniform(-2, 2, (500, 3))
    sym = FourierField.fit(sample_grid(g, 8))
    average = np.mean([g(x @ q.T) for q in TD_OPERATORS], axis=0)  # brute-force group average
    assert np.abs(sym(x) - average).max() < 1e-9
    for q in TD_OPERATORS:
        assert np.abs(sym(x @ q.T) - sym(x)).max() < 1e-9
    # symmetrizing an unsymmetric fit afterwards gives the same field
    later = FourierField.fit(sample_grid(g, 8), symmetric=False).symmetrize()
    assert np.abs(later(x) - sym(x)).max() < 1e-9


def test_gyroid_fit_symmetric_is_invariant():
    # the gyroid is chiral (no mirror symmetry): its T_d average vanishes identically, which is
    # the invariant field closest to it; the fit must say so rather than invent terms
    sym = FourierField.fit(sample_grid(gyroid, 16))
    x = np.random.default_rng(3).uniform(-1, 1, (300, 3))
    for q in TD_OPERATORS:
        assert np.abs(sym(x @ q.T) - sym(x)).max() < 1e-9
    assert np.abs(sym(x)).max() < 1e-9


@pytest.mark.parametrize("kind", ["schwarz_p", "diamond", "iwp"])
def test_td_symmetric_tpms_reproduced_by_symmetric_fit(kind):
    f = TPMSField(kind)
    x = np.random.default_rng(4).uniform(-2, 2, (1000, 3))
    for q in TD_OPERATORS:  # these surfaces have T_d among their symmetries
        assert np.abs(f(x @ q.T) - f(x)).max() < 1e-9
    fit = FourierField.fit(sample_grid(f, 8))
    assert np.abs(fit(x) - f(x)).max() < 1e-6


def test_inside_outside_fit_is_symmetric_and_roughly_right():
    # a ball of radius 0.3 off the origin; inside/outside samples are not band limited
    inside = sample_grid(lambda p: np.linalg.norm(p - [0.1, 0.05, 0], axis=1) < 0.3, 16) > 0.5
    fit = FourierField.fit_inside_outside(inside, symmetric=False)
    x = -0.5 + np.arange(16) / 16
    pts = np.stack(np.meshgrid(x, x, x, indexing="ij"), axis=-1).reshape(-1, 3)
    assert np.array_equal(fit(pts) < 0, inside.reshape(-1))  # interpolates the samples
    y = np.random.default_rng(5).uniform(-0.5, 0.5, (300, 3))
    for terms in (None, 400):
        sym = FourierField.fit_inside_outside(inside, max_terms=terms)
        for q in TD_OPERATORS:
            assert np.abs(sym(y @ q.T) - sym(y)).max() < 1e-9


@settings(max_examples=30, deadline=None)
@given(st.floats(0.3, 3.0), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1), st.floats(-3, 3))
def test_tpms_placement_and_cell(cell, a, b, c, angle):
    placement = Swirl(angle, [a + 2, b, c], [a, b, c], 1.3)
    f = TPMSField("gyroid", cell, placement)
    local = np.random.default_rng(6).uniform(-2, 2, (50, 3))
    world = placement.apply_points(local * cell)
    assert np.allclose(f(world), gyroid(local), atol=1e-9)


def test_fourier_field_placement_and_roundtrip(tmp_path):
    rng = np.random.default_rng(7)
    g = random_band_limited(rng, 2)
    fit = FourierField.fit(sample_grid(g, 8), symmetric=False)
    save_npz(tmp_path / "c.npz", fit.arrays())
    placement = Rotation(0.4, [1, 2, 3], [0.5, 0, 0])
    back = FourierField.load(tmp_path / "c.npz", cell=2.0, placement=placement)
    local = rng.uniform(-1, 1, (100, 3))
    assert np.abs(back(placement.apply_points(2.0 * local)) - g(local)).max() < 1e-6


@pytest.mark.parametrize("variant,level", [("network", 0.3), ("sheet", 0.4)])
def test_implicit_filter_matches_direct_evaluation(variant, level):
    lat = load_lattice("bcc", {"n": 6})
    field = TPMSField("gyroid", 2.5)
    ev = FilteredLattice(lat, ImplicitFilter(field, level, variant)).evaluate()
    full = lat.evaluate()
    v = gyroid(full.center / 2.5)
    keep = np.abs(v) < level if variant == "sheet" else v < level
    assert {tuple(x) for x in ev.node_index} == {tuple(x) for x in full.node_index[keep]}
    alive = keep[full.beam_nodes[:, 0]] & keep[full.beam_nodes[:, 1]]
    assert {tuple(x) for x in ev.beam_index} == {tuple(x) for x in full.beam_index[alive]}
    assert 0 < len(ev.node_index) < len(full.node_index)


def test_parse_implicit():
    f = parse_implicit("gyroid:cell=2,level=0.2,sheet,origin=1/0/0")
    assert f.variant == "sheet" and f.level == 0.2 and isinstance(f.field, TPMSField)
    assert np.allclose(f.field([[1, 0, 0]]), gyroid(np.zeros((1, 3))))
    assert parse_implicit("iwp:cell=1x2x3").field.cell.tolist() == [1, 2, 3]


@pytest.mark.parametrize("bad", ["blob", "gyroid:cell=0", "gyroid:cell=x", "gyroid:level=1,size=2", "gyroid:what",
                                 "gyroid:sheet", "fourier", "fourier:file=/nonexistent.npz", "gyroid:variant=foam"])
def test_parse_implicit_bad(bad):
    with pytest.raises(PleError):
        parse_implicit(bad)


def test_fit_bad_samples():
    with pytest.raises(PleError):
        FourierField.fit(np.zeros((4, 4)))
    with pytest.raises(PleError):
        FourierField.fit(np.full((4, 4, 4), np.nan))
    with pytest.raises(PleError):
        FourierField.fit_inside_outside(np.zeros((4, 4, 4)))


def test_orbit_evaluation_equals_term_by_term_sum():
    # symmetric fields are evaluated by T_d orbits (cos/sin tables per axis); the plain per-term
    # sum of the same coefficients must agree
    rng = np.random.default_rng(8)
    sym = FourierField.fit(sample_grid(random_band_limited(rng, 5), 16))
    plain = FourierField(sym.freqs, sym.coeffs, sym.n)
    assert sym.symmetric and not plain.symmetric and np.any(sym.freqs[:, 2] < 0)
    x = rng.uniform(-2, 2, (2000, 3))
    assert np.abs(sym(x) - plain(x)).max() < 1e-9 * np.abs(plain(x)).max()
