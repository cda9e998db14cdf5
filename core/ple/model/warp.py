"""Rectified steady warps: design by global shape (thesis §3.1–3.4, §3.8).

A regular slab or brick (node-group (i, j, k) = template + (i, j, k) in cell units) is warped
by the steady map ``M(u, v, w) = W**w ∘ V**v ∘ U**u (O)`` (§3.1; parameters u = x / nu,
v = y / nv, w = z / nw, so the whole lattice spans [0, 1) per direction). A slab (no W) keeps
its thickness: a point at height z maps as ``V**v ∘ U**u (O + z e_z)``. Warped balls are
beans; each template node is *rectified* on its own as the sphere through the images of four
equally spaced points of the pre-warp ball (§3.4). The rectified node-groups are then the
steady pattern ``N[i, j, k] = W**(k/nw) ∘ V**(j/nv) ∘ U**(i/nu) ∘ N[0, 0, 0]`` (§3.2), so the
result is an ordinary similarity steady lattice: its nodes, beams and hubs are steady (§3.3)
and every fast path (RangeFinder, closed-form area/volume) applies. Beams that would leave
the lattice are not made (§3.8: boundary hubs differ; the measures count only present beams).
"""

from __future__ import annotations

import numpy as np

from ..algebra.similarity import Similarity
from ..algebra.vectors import Pt
from ..errors import PleError, echo
from .lattice import Lattice, Node

# four equally spaced points on the unit sphere (a regular tetrahedron), §3.4
TETRAHEDRON = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float) / np.sqrt(3.0)


def circumsphere(points) -> tuple[np.ndarray, float]:
    """Centre and radius of the sphere through four points (4, 3); PleError if coplanar."""
    p = np.asarray(points, dtype=float).reshape(4, 3)
    a = 2.0 * (p[1:] - p[0])
    b = (p[1:] ** 2).sum(axis=1) - (p[0] ** 2).sum()
    scale = max(float(np.abs(p - p[0]).max()), 1e-300)
    if abs(np.linalg.det(a)) <= 1e-12 * (2 * scale) ** 3:
        raise PleError("rectification: the four warped points are coplanar (the warp flattens a node)")
    c = np.linalg.solve(a, b)
    return c, float(np.linalg.norm(p[0] - c))


def steady_map(u: Similarity, v: Similarity, w: Similarity, origin, params, lift=None) -> np.ndarray:
    """``M(u, v, w) = W**w ∘ V**v ∘ U**u (O + lift)`` at parameter rows (N, 3) (§3.1 steady map);
    ``lift`` (N, 3) offsets the origin per row (a slab's thickness), default none."""
    t = np.asarray(params, dtype=float).reshape(-1, 3)
    o = np.zeros((len(t), 4))
    o[:, :3] = Pt(origin)
    if lift is not None:
        o[:, :3] += np.asarray(lift, dtype=float).reshape(-1, 3)
    o[:, 3] = 1.0
    m = w.power_matrices(t[:, 2]) @ v.power_matrices(t[:, 1]) @ u.power_matrices(t[:, 0])
    return np.einsum("nab,nb->na", m, o)[:, :3]


class RectifiedWarp:
    """The steady map of a rectified warp; ``lattice`` builds the rectified lattice."""

    def __init__(self, u: Similarity, v: Similarity, w: Similarity | None = None, origin=(0.0, 0.0, 0.0),
                 counts=(8, 8, 1)):
        for name, s in (("U", u), ("V", v), ("W", w)):
            if s is not None and not isinstance(s, Similarity):
                raise PleError(f"rectified warp: {name} must be a Similarity, got {type(s).__name__}")
        try:
            nu, nv, nw = (int(c) for c in tuple(counts) + (1,) * (3 - len(tuple(counts))))
        except (TypeError, ValueError):
            raise PleError(f"rectified warp: counts {echo(counts)} must be integers") from None
        if min(nu, nv, nw) < 1:
            raise PleError(f"rectified warp: counts {echo(counts)} must be at least 1")
        self.u, self.v = u, v
        self.slab = w is None  # a slab: height z lifts the origin (innermost), W is the identity
        self.w = Similarity() if w is None else w
        if self.slab and nw != 1:
            raise PleError("rectified warp: a slab (no W) has one layer; give W for a brick")
        self.origin = Pt(origin)
        self.counts = (nu, nv, nw)

    def params(self, cell_points) -> np.ndarray:
        """Cell-unit points (x, y, z) as parameters (x / nu, y / nv, z / nw)."""
        return np.asarray(cell_points, dtype=float).reshape(-1, 3) / np.array(self.counts, dtype=float)

    def __call__(self, cell_points) -> np.ndarray:
        """The warp of points given in cell units (the regular lattice's coordinates)."""
        p = np.asarray(cell_points, dtype=float).reshape(-1, 3)
        if self.slab:
            lift = np.zeros_like(p)
            lift[:, 2] = p[:, 2]
            return steady_map(self.u, self.v, self.w, self.origin, self.params(p * [1, 1, 0]), lift)
        return steady_map(self.u, self.v, self.w, self.origin, self.params(p))

    def rectify(self, center, radius: float) -> tuple[np.ndarray, float]:
        """The rectified node of a pre-warp ball (cell units): sphere through 4 warped points (§3.4)."""
        return circumsphere(self(Pt(center) + float(radius) * TETRAHEDRON))

    def lattice(self, template: Lattice) -> Lattice:
        """The rectified steady lattice of a regular template (nodes in cell units, beam-patterns
        with their offsets): template rectified, U, V, W steps of 1/nu, 1/nv, 1/nw (§3.2)."""
        template.validate()
        out = template.copy()
        out.nodes = []
        for n in template.nodes:
            c, r = self.rectify(n.center, n.radius)
            out.nodes.append(Node(c, r, n.name))
        nu, nv, nw = self.counts
        out.set_u(nu, self.u ** (1.0 / nu))
        out.set_v(nv, self.v ** (1.0 / nv))
        out.set_w(nw, self.w ** (1.0 / nw))
        out.meta = dict(template.meta, rectified_warp=True)
        return out


def rectified_warp(template: Lattice, u: Similarity, v: Similarity, w: Similarity | None = None,
                   origin=(0.0, 0.0, 0.0), counts=(8, 8, 1)) -> Lattice:
    """A regular slab/brick (``template`` in cell units) warped by the steady map of U, V, W
    from ``origin`` and rectified (§3.1–3.4); ``counts`` groups per direction."""
    return RectifiedWarp(u, v, w, origin, counts).lattice(template)
