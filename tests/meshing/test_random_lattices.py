"""Property: every steady lattice meshes, or says clearly why not (CHoCC paper 001_ §5–6).

A few hundred random lattices, seed-fixed: 1–3 balls anywhere in the cell with radii up to half
the cell, up to 12 beam-patterns between them with offsets in {−1, 0, 1}³, U, V, W random
similarities near the unit translations (small rotations, scalings within ±6 %), sometimes a
stencil filter, over 2 × 2 × 2 groups. Each must give, through the public ``tessellate``, a
watertight and consistently oriented mesh in the ``cnt`` and ``refined`` styles whose refined
volume matches the Monte Carlo volume of the exact union of its balls and cone-beams
(``union_oracle``), or raise a PleError (never another exception).

Tolerance of the volume: |V_mesh / V_MC − 1| ≤ 2.5 % + 4σ. σ is the oracle's standard error
from its sample count (8,000 points per element: σ ≈ 0.3–0.7 %); 2.5 % bounds the refined
mesh's own deficit at the 3 levels used here: its vertices lie on the exact surface, and every
beam's ring has at least 3·2³ = 24 of them (an inscribed regular 24-gon misses 1.1 % of its disk;
the CNT's uneven spacing of the ring, up to about twice that). Measured: −2.2 % … +0.4 % at
3 levels, −1.4 % … +0.7 % at the default 4 (too slow for a few hundred lattices here; the
degenerate-junction tests use 4 levels and 1 % + 4σ).

Random lattices are mostly *unclean* (crossing diagonals, thick balls): they go through the
union path (manifold3d's local unions), 0.1–13 s per lattice (both styles); this test classifies
them (the hub templates and the detector run, no traceback) and unites nine fixed ones in
``test_unclean_random_lattices_are_united`` (``PLE_RANDOM_LATTICES=all`` unites every one).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from ple import Lattice
from ple.algebra.similarity import Similarity
from ple.errors import PleError
from ple.filters.stencil import Stencil
from ple.meshing.tessellate import Tessellator, tessellate
from scipy.spatial.transform import Rotation
from union_oracle import union_volume

CASES = int(os.environ.get("PLE_RANDOM_LATTICES", "200").replace("all", "400"))
CHUNK = 20
LEVELS = 3
DEFICIT = 0.025  # the refined mesh's own volume deficit at LEVELS (module docstring)
SAMPLES = 8000  # per element of the oracle
ALL = os.environ.get("PLE_RANDOM_LATTICES") == "all"  # 400 lattices, every unclean one united
KNOWN = ("same direction", "inside the other ball of its beam", "length 0")  # degenerate junctions
OFFSETS = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]


def _similarity(rng, axis: int) -> Similarity:
    m = np.eye(4)
    m[:3, :3] = rng.uniform(0.94, 1.06) * Rotation.from_rotvec(rng.normal(size=3) * 0.06).as_matrix()
    m[:3, 3] = np.eye(3)[axis] + rng.normal(size=3) * 0.08
    return Similarity.from_matrix(m)


def random_lattice(seed: int) -> Lattice:
    """A random steady lattice of 2 × 2 × 2 groups (see the module docstring). One in twenty
    repeats a beam-pattern reversed (the same beams twice: a degenerate junction at every hub)."""
    rng = np.random.default_rng(seed)
    lat = Lattice()
    balls = int(rng.integers(1, 4))
    for k in range(balls):
        thick = rng.random() < 0.15
        lat.add_node(rng.uniform(0, 1, 3) if k else np.zeros(3), rng.uniform(0.02, 0.5 if thick else 0.12))
    seen: set = set()
    for _ in range(int(rng.integers(1, 13))):
        n1, n2 = (int(x) for x in rng.integers(0, balls, 2))
        off = OFFSETS[rng.integers(len(OFFSETS))]
        reverse = (n2, n1, tuple(-x for x in off))
        if (n1 == n2 and off == (0, 0, 0)) or (n1, n2, off) in seen or reverse in seen:
            continue
        seen.add((n1, n2, off))
        lat.add_beam(n1, n2, *off)
    if seen and rng.random() < 0.05:
        n1, n2, off = sorted(seen)[0]
        lat.add_beam(n2, n1, *(-x for x in off))
    for axis, name in enumerate("uvw"):
        getattr(lat, f"set_{name}")(2, _similarity(rng, axis))
    if rng.random() < 0.25:
        lat.set_filter(Stencil(rng.random((2, 2, 2, balls)) < 0.8))
    return lat


def _check(seed: int, unite: bool) -> str:
    """The outcome of one random lattice: 'clean', 'unclean' (meshed through the union path),
    'unclean, not meshed' or 'PleError: …'; raises AssertionError on a wrong mesh."""
    lat = random_lattice(seed)
    try:
        report, ev = Tessellator(lat, lat.region(), "cnt", 0, 16).find_unclean()
        unclean = len(report.nodes) > 0
        if unclean and not unite:
            return "unclean, not meshed"
        est, err = union_volume(ev.center, ev.radius, ev.beam_nodes, SAMPLES, seed)
        for style in ("cnt", "refined"):  # refined checks itself: its hubs reach further
            mesh = tessellate(lat, style=style, levels=LEVELS, unclean=report if style == "cnt" else None)
            assert mesh.is_watertight and mesh.is_winding_consistent, f"seed {seed} {style}: not closed"
            assert np.isfinite(mesh.vertices).all(), f"seed {seed} {style}: non-finite vertices"
            if style == "refined":
                rel = mesh.volume / est - 1
                assert abs(rel) <= DEFICIT + 4 * err / est, f"seed {seed}: volume {rel:+.2%} (σ {err / est:.2%})"
    except PleError as e:
        return f"PleError: {str(e).split(': ', 1)[-1].split(' [')[0][:60]}"
    return "unclean" if unclean else "clean"


@pytest.mark.parametrize("first", range(0, CASES, CHUNK))
def test_random_steady_lattices_mesh_or_say_why(first):
    outcomes: dict = {}
    for seed in range(first, first + CHUNK):
        outcomes.setdefault(_check(seed, ALL), []).append(seed)
    print({k: len(v) for k, v in outcomes.items()})
    assert outcomes.get("clean"), "no clean lattice in a chunk: the generator drifted"
    errors = {k: v for k, v in outcomes.items() if k.startswith("PleError")}
    # a beam-pattern repeated reversed (on purpose), a thick ball swallowing a thin one it is joined to
    assert all(any(why in k for why in KNOWN) for k in errors), errors


UNCLEAN = [1, 8, 14, 16, 23, 27, 29, 35, 36, 61]  # unclean lattices the union path meshes in about a second
# (14 and 27 were refused until the ring polygons, which the union is opened along, were left out
# of on_grid's checks; 61's batched unions once lost a cluster's second piece: a union opened
# along its rings may fall apart in several)


@pytest.mark.parametrize("seed", UNCLEAN)
def test_unclean_random_lattices_are_united(seed):
    assert _check(seed, True) == "unclean"
