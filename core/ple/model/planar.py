"""Planar steady 2-maps from five points, planar shapes rolled onto cones, and seamless
self-overlap by snapping a corner to a grid vertex (thesis §2.6.5, §4.3.2, §4.4.3).

- ``SteadyMap2.from_five(A, B, C, D, E)``: U = Similarity({A,E},{E,B})**2 and
  V = Similarity({A,B},{C,D}), so that M(u, v) = V**v ∘ U**u (A) passes through A = M(0,0),
  B = M(1,0), C = M(0,1), D = M(1,1) and E = M(.5,0) (§2.6.5).
- ``ShapeOntoCone``: the pipeline at the end of §4.3.2 as one call: four non-coplanar points
  define a BeCOTS cone; its Unbend gives their preimages on a plane; a planar shape placed
  relative to the preimages is rolled onto the cone by the BeCOTS map ∘ the inverse COTS map
  (conformal, and an isometry: geodesic lengths are kept).
- ``snap_corner``: §4.4.3, Fig. 4.12: corner D = M(1,0) is moved onto the grid vertex (i, j)
  of the tiling with (nu, nv) tiles, by adjusting U so that S(1 - i/nu, -j/nv) is a whole
  number of turns; vertices (a, b) and (a + nu - i, b - j) then coincide: a seamless tiling.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..algebra.similarity import Similarity
from ..algebra.vectors import Pt
from ..errors import PleError, echo
from .becots import BeCOTSField
from .lattice import Lattice


class SteadyMap2:
    """A steady 2-map ``M(u, v) = V**v ∘ U**u (O)`` (§2.6.4)."""

    def __init__(self, u: Similarity, v: Similarity, origin):
        self.u, self.v, self.origin = u, v, Pt(origin)

    @staticmethod
    def from_five(a, b, c, d, e) -> SteadyMap2:
        """§2.6.5: A = M(0,0), B = M(1,0), C = M(0,1), D = M(1,1), E = M(.5,0) (planar points)."""
        pa, pb, pc, pd, pe = (Pt(p) for p in (a, b, c, d, e))
        z = pa[2]
        if any(abs(p[2] - z) > 1e-12 * max(1.0, float(np.abs(p).max())) for p in (pb, pc, pd, pe)):
            raise PleError("five-point map: the points must lie in one plane z = const")
        u = Similarity.from_point_pairs(pa, pe, pe, pb) ** 2.0
        v = Similarity.from_point_pairs(pa, pb, pc, pd)
        return SteadyMap2(u, v, pa)

    def __call__(self, u, v) -> np.ndarray:
        """Points M(u, v) (n, 3) for arrays u, v (broadcast)."""
        u, v = np.broadcast_arrays(np.asarray(u, float).reshape(-1), np.asarray(v, float).reshape(-1))
        m = self.v.power_matrices(v) @ self.u.power_matrices(u)
        return m[:, :3, :3] @ self.origin + m[:, :3, 3]

    def lattice(self, template: Lattice, counts=(4, 4)) -> Lattice:
        """The steady slab of the map: node-group (i, j) = V**(j/nv) ∘ U**(i/nu) ∘ template, for
        (nu + 1) x (nv + 1) groups (template nodes around O; corner groups at the corners)."""
        try:
            nu, nv = (int(c) for c in counts)
        except (TypeError, ValueError):
            raise PleError(f"counts {echo(counts)}: expected two integers") from None
        if nu < 1 or nv < 1:
            raise PleError(f"counts {echo(counts)}: at least one tile per direction")
        out = template.copy()
        out.set_u(nu + 1, self.u ** (1.0 / nu))
        out.set_v(nv + 1, self.v ** (1.0 / nv))
        return out


class ShapeOntoCone:
    """Roll a planar shape onto the cone of four non-coplanar points (§4.3.2, last paragraph)."""

    def __init__(self, a, b, c, d, branch=(0, 0)):
        self.cone = BeCOTSField.from_corners(a, b, c, d, branch)
        if self.cone.kind != "cone" or self.cone.is_planar:
            raise PleError("shape onto cone: the four points must be non-coplanar and define a cone "
                           f"(they define a {'planar COTS' if self.cone.kind == 'cone' else self.cone.kind} field)")
        self.flat = self.cone.unbent()
        self.e1, self.e2 = self.flat.frame

    def plane_coordinates(self, pts) -> np.ndarray:
        """2D coordinates (n, 2) on the unrolled plane: origin the apex F, x toward A."""
        p = np.asarray(pts, float).reshape(-1, 3) - self.flat.apex
        return np.stack([p @ self.e1, p @ self.e2], axis=1)

    def preimages(self) -> np.ndarray:
        """(4, 2): the unrolled corners A, B, C, D in plane coordinates (step 2 of the pipeline)."""
        return self.plane_coordinates(self.flat.corners)

    def __call__(self, pts2d, placement: Similarity | None = None) -> np.ndarray:
        """Points (n, 3) on the cone of planar points (n, 2), placed in plane coordinates by
        ``placement`` (a planar similarity, default none): BeCOTS map ∘ inverse COTS map."""
        q = np.asarray(pts2d, float).reshape(-1, 2)
        if placement is not None:
            q = placement.apply_points(np.concatenate([q, np.zeros((len(q), 1))], axis=1))[:, :2]
        fa = float(np.linalg.norm(self.flat.a - self.flat.apex))
        r = np.linalg.norm(q, axis=1)
        if np.any(r <= 1e-12 * fa):
            raise PleError("shape onto cone: a point sits on the apex F")
        rho, theta = np.log(r / fa), np.arctan2(q[:, 1], q[:, 0])  # A sits at theta = 0 on the plane
        xy = np.linalg.solve(self.flat.jacobian, np.stack([rho, theta]))  # inverse COTS map (Eq. 4.12)
        return self.cone.points(xy[0], xy[1])


def snap_corner(fld: BeCOTSField, counts, vertex) -> BeCOTSField:
    """The field with corner D = M(1,0) moved onto grid vertex (i, j) of the (nu, nv) tiling
    (§4.4.3): U changes so that S(1 - i/nu, -j/nv) turns by the nearest whole number of turns
    and dilates by 1; A, the apex, the axis and V stay."""
    if fld.kind != "cone":
        raise PleError(f"snap: a {fld.kind} field does not wrap around an apex")
    try:
        nu, nv = (int(c) for c in counts)
        i, j = (int(c) for c in vertex)
    except (TypeError, ValueError):
        raise PleError(f"snap: counts {echo(counts)} and vertex {echo(vertex)} must be integer pairs") from None
    p, q = 1.0 - i / nu, -j / nv  # S(p, q) must be a whole number of turns
    if abs(p) < 1e-12:
        raise PleError(f"snap: vertex {echo(vertex)} lies on D's own column; choose i != nu")
    wu, (rv, wv) = fld.u[1], fld.v
    k = round((wu * p + wv * q) / (2 * math.pi))
    if k == 0:
        raise PleError(f"snap: the tiling does not wrap around the apex to reach vertex {echo(vertex)} (0 turns)")
    new_u = (-rv * q / p, (2 * math.pi * k - wv * q) / p)
    return replace(fld, u=new_u)
