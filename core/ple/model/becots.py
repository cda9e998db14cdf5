"""BeCOTS slabs (thesis §4, §6.3): corner-operated tran-similar fields, maps, patterns, lattices,
stacks and constant-radius connectors.

A BeCOTS field is ``S(x, y) = U**x ∘ V**y`` with commuting similarities U, V that share one
fixed point F and one rotation axis T (Eq. 4.3–4.4). In *log-polar* coordinates about (F, T)
— ``rho = ln(|FP| / |FA|)`` and the angle ``theta`` about T — S acts as the translation
``(rho, theta) += x (ru, wu) + y (rv, wv)``, which is what makes the map tran-similar, the
inverse closed-form (Eq. 4.10–4.12) and the BIQ constant-time (§8). Three kinds exist:

- ``"cone"``: U, V dilate about F (the general BeCOTS; planar COTS when A lies in the plane
  through F normal to T); ``ru = ln m_u``, ``rv = ln m_v``;
- ``"cylinder"``: both factors are 1 (two screws about one axis, the degenerate cone with its
  apex at infinity); ``rho`` is then the height along T and ``ru``, ``rv`` are slides;
- ``"translation"``: U, V are translations (parallelogram corners, a regular slab).

Corner order (thesis §4.2): M(0,0)=A, M(0,1)=B, M(1,1)=C, M(1,0)=D, so U = SIM(A,B,D,C)
takes A to D and V = SIM(A,D,B,C) takes A to B. Lattice convention (SPEC §5, §4.4.1):
node-group (i, j) is ``S(i/nu, j/nv)`` applied to the template group, for 0 <= i < nu and
0 <= j < nv (``closed=True`` adds the last row and column, i = nu and j = nv, so the
groups reach the edges D–C and B–C).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..algebra.series import geometric_sum
from ..algebra.similarity import Similarity, Translation
from ..algebra.vectors import as3, unit
from ..errors import PleError, echo

TWO_PI = 2.0 * math.pi
NEAR_UNIT_FACTOR = 1e-12  # |ln m| below this: no dilation (m == 1), the cylinder/translation kinds
PARALLEL_TOL = 1e-9  # unit-vector differences below this: the edges are parallel (no rotation)
CORNER_TOL = 1e-7  # relative miss of a rebuilt corner above which the corners admit no field
DOMAIN_TOL = 1e-9  # slack on the unit square when inverting
KINDS = ("cone", "cylinder", "translation")


@dataclass(frozen=True)
class BeCOTSField:
    """A BeCOTS field and its map ``M(x, y) = S(x, y) ∘ A`` (see the module doc).

    ``apex`` F (3,), ``axis`` T (3,) unit, ``a`` corner A (3,), ``u = (ru, wu)`` and
    ``v = (rv, wv)`` the log-polar steps of U and V (``ru = ln m_u`` for a cone, a slide for a
    cylinder); for the translation kind ``tu``, ``tv`` are the translation vectors of U and V.
    """

    kind: str
    a: np.ndarray
    apex: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    u: tuple = (0.0, 0.0)
    v: tuple = (0.0, 0.0)
    tu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tv: np.ndarray = field(default_factory=lambda: np.zeros(3))

    # ----- construction -----------------------------------------------------------------------
    @staticmethod
    def from_corners(a, b, c, d, branch=(0, 0)) -> BeCOTSField:
        """The field with M(0,0)=A, M(0,1)=B, M(1,1)=C, M(1,0)=D (§4.3.4, Eq. 4.8–4.9).

        ``branch = (ku, kv)`` adds ``2π ku`` and ``2π kv`` full turns to U's and V's rotation
        angles (the corners stay put; the map wraps more around its cone)."""
        pts = [as3(p, f"corner {n}") for p, n in zip((a, b, c, d), "ABCD")]
        ku, kv = _branch(branch)
        A, B, C, D = pts
        names = "ABCD"
        scale = max(np.linalg.norm(p - q) for p in pts for q in pts)
        for x in range(4):
            for y in range(x + 1, 4):
                if np.linalg.norm(pts[x] - pts[y]) <= 1e-12 * max(scale, 1e-300):
                    raise PleError(f"corners {names[x]} and {names[y]} coincide: a BeCOTS needs four distinct corners")
        sv = np.linalg.svd(np.array([B - A, C - A, D - A]), compute_uv=False)
        if sv[1] <= 1e-9 * sv[0]:
            raise PleError("corners A, B, C, D are collinear: their map would be a curve, not a slab")
        # special case: parallelogram corners -> U, V are translations (regular slab)
        if (np.linalg.norm((B - A) - (C - D)) <= 1e-12 * scale and np.linalg.norm((D - A) - (C - B)) <= 1e-12 * scale):
            if (ku, kv) != (0, 0):
                raise PleError("branch: a translation field (parallelogram corners) has no rotation to wrap")
            return BeCOTSField("translation", A, tu=D - A, tv=B - A)
        axis = _axis_from_corners(A, B, C, D, sv)
        if axis @ np.cross(D - A, B - A) < 0:  # orient T with the u × v normal at A: Raise(z > 0) goes that way
            axis = -axis
        fld = _field_with_axis(A, B, C, D, axis, ku, kv)
        miss = np.abs(fld.points(np.array([0.0, 0.0, 1.0, 1.0]), np.array([0.0, 1.0, 1.0, 0.0])) - np.array(pts))
        worst = float(np.linalg.norm(miss, axis=1).max())
        if not worst <= CORNER_TOL * scale:
            raise PleError(f"corners A, B, C, D admit no BeCOTS field (the closest misses a corner by {worst:.3g})")
        return fld

    @staticmethod
    def from_controls(warp, beta: float = math.pi / 2, placement: Similarity | None = None,
                      branch=(0, 0)) -> BeCOTSField:
        """A cone field from its separate controls (§4.3.3): ``warp = (ln m_u, w_u, ln m_v,
        w_v)`` of the flat COTS (4 DoF), the bend ``beta`` (cone half-angle between FA and
        the axis, π/2 = flat) and the ``placement`` similarity (7 DoF) of the canonical frame
        F = origin, A = (1, 0, 0), flat normal = z."""
        lu, wu, lv, wv = (float(x) for x in warp)
        if not all(math.isfinite(x) for x in (lu, wu, lv, wv)):
            raise PleError(f"warp {echo(warp)}: values must be finite")
        ku, kv = _branch(branch)
        flat = BeCOTSField("cone", np.array([1.0, 0.0, 0.0]), np.zeros(3), np.array([0.0, 0.0, 1.0]),
                           (lu, wu + TWO_PI * ku), (lv, wv + TWO_PI * kv))
        flat._check_map()
        out = flat.bent(beta)
        return out.placed(placement) if placement is not None else out

    def _check_map(self) -> None:
        if self.kind == "translation":
            if np.linalg.norm(np.cross(self.tu, self.tv)) <= 1e-12 * np.linalg.norm(self.tu) * np.linalg.norm(self.tv):
                raise PleError("the translations of U and V are parallel: the map would be a line")
            return
        if np.linalg.norm(self.radial) <= 1e-12 * max(1.0, np.linalg.norm(self.a - self.apex)):
            raise PleError("corner A lies on the field's axis: the map degenerates to a line")
        (ru, wu), (rv, wv) = self.u, self.v
        det = ru * wv - rv * wu
        if not abs(det) > 1e-12 * (abs(ru) + abs(rv)) * (abs(wu) + abs(wv)) or det == 0.0:
            raise PleError("U and V move along the same conchospiral: the map would be a curve, not a slab")

    # ----- basic quantities ---------------------------------------------------------------------
    @property
    def radial(self) -> np.ndarray:
        """Component of FA perpendicular to the axis."""
        fa = self.a - self.apex
        return fa - (fa @ self.axis) * self.axis

    @property
    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """(e1, e2): e1 along the radial part of FA, e2 = T × e1; theta is measured from e1."""
        e1 = unit(self.radial)
        return e1, np.cross(self.axis, e1)

    @property
    def jacobian(self) -> np.ndarray:
        """2x2 matrix taking (x, y) to log-polar (rho, theta) (Eq. 4.10)."""
        (ru, wu), (rv, wv) = self.u, self.v
        return np.array([[ru, rv], [wu, wv]])

    @property
    def factors(self) -> tuple[float, float]:
        """Dilation factors (m_u, m_v) of U and V."""
        if self.kind == "cone":
            return math.exp(self.u[0]), math.exp(self.v[0])
        return 1.0, 1.0

    @property
    def beta(self) -> float:
        """Cone half-angle between FA and the axis T (π/2 for a planar COTS), §4.3.2."""
        if self.kind != "cone":
            raise PleError(f"a {self.kind} field has no cone angle")
        fa = unit(self.a - self.apex)
        return math.acos(float(np.clip(fa @ self.axis, -1.0, 1.0)))

    @property
    def height(self) -> float:
        """Height parameter z = FA·T of the raise family (§4.3.1)."""
        return float((self.a - self.apex) @ self.axis)

    @property
    def is_planar(self) -> bool:
        """A planar COTS: translation kind, or a cone with A in the plane through F normal to T."""
        if self.kind == "translation":
            return True
        return self.kind == "cone" and abs(self.height) <= 1e-12 * np.linalg.norm(self.a - self.apex)

    def similarity(self, x: float, y: float) -> Similarity:
        """``S(x, y)`` as a canonical Similarity (angles beyond 2π are kept)."""
        if self.kind == "translation":
            return Translation(x * self.tu + y * self.tv)
        (ru, wu), (rv, wv) = self.u, self.v
        rho, theta = x * ru + y * rv, x * wu + y * wv
        if self.kind == "cone":
            return Similarity(math.exp(rho), theta, tuple(self.axis), tuple(self.apex), 0.0)
        return Similarity(1.0, theta, tuple(self.axis), tuple(self.apex), rho)

    @property
    def U(self) -> Similarity:  # noqa: N802 - thesis names
        return self.similarity(1.0, 0.0)

    @property
    def V(self) -> Similarity:  # noqa: N802
        return self.similarity(0.0, 1.0)

    @property
    def corners(self) -> np.ndarray:
        """(4, 3): A = M(0,0), B = M(0,1), C = M(1,1), D = M(1,0)."""
        return self.points(np.array([0.0, 0.0, 1.0, 1.0]), np.array([0.0, 1.0, 1.0, 0.0]))

    # ----- map and inverse ----------------------------------------------------------------------
    def apply(self, x, y, pts) -> np.ndarray:
        """``S(x_n, y_n)`` applied to points ``pts`` (n, 3) (or one point (3,)), vectorized."""
        x, y = np.broadcast_arrays(np.asarray(x, float).reshape(-1), np.asarray(y, float).reshape(-1))
        p = np.broadcast_to(np.asarray(pts, float).reshape(-1, 3), (len(x), 3))
        if self.kind == "translation":
            return p + x[:, None] * self.tu + y[:, None] * self.tv
        (ru, wu), (rv, wv) = self.u, self.v
        rho, theta = x * ru + y * rv, x * wu + y * wv
        frame = np.stack([*self.frame, self.axis])  # rows e1, e2, T
        loc = (p - self.apex) @ frame.T  # coordinates about F: rotation about T turns (e1, e2)
        c, s = np.cos(theta), np.sin(theta)
        turned = np.stack([loc[:, 0] * c - loc[:, 1] * s, loc[:, 0] * s + loc[:, 1] * c, loc[:, 2]], axis=1)
        if self.kind == "cone":
            return self.apex + np.exp(rho)[:, None] * (turned @ frame)
        turned[:, 2] += rho  # cylinder: slide along T
        return self.apex + turned @ frame

    def points(self, x, y) -> np.ndarray:
        """The map ``M(x, y) = S(x, y) ∘ A`` for arrays x, y (n,): points (n, 3)."""
        return self.apply(x, y, self.a)

    def log_polar(self, pts) -> tuple[np.ndarray, np.ndarray]:
        """(rho, theta) of points (n, 3), theta in (-π, π] from e1 (Eq. 4.10's m and w)."""
        p = np.asarray(pts, float).reshape(-1, 3) - self.apex
        e1, e2 = self.frame
        theta = np.arctan2(p @ e2, p @ e1)
        if self.kind == "cone":
            return np.log(np.linalg.norm(p, axis=1) / np.linalg.norm(self.a - self.apex)), theta
        return (p - (self.a - self.apex)) @ self.axis, theta

    def inverse(self, pts, tol: float = 1e-9, domain=((0.0, 1.0), (0.0, 1.0))) -> list[list[tuple[float, float]]]:
        """Every (x, y) in ``domain`` (default the unit square) with M(x, y) = Q, over all
        branches k of the angle (§4.3.5, Eq. 4.10–4.12), for each point Q (n, 3).

        Points off the cone (M(x, y) farther than ``tol`` × the corner size from Q) get no
        answers; a self-overlapping map gives several answers per point."""
        q = np.asarray(pts, float).reshape(-1, 3)
        if not np.all(np.isfinite(q)):
            raise PleError("inverse: points must be finite")
        (x0, x1), (y0, y1) = domain
        scale = float(np.linalg.norm(self.corners - self.corners.mean(axis=0), axis=1).max())
        out: list[list[tuple[float, float]]] = [[] for _ in range(len(q))]
        if self.kind == "translation":
            basis = np.stack([self.tu, self.tv], axis=1)
            xy = np.linalg.lstsq(basis, (q - self.a).T, rcond=None)[0].T
            idx = np.arange(len(q))
        else:
            rho, theta = self.log_polar(q)
            jinv = np.linalg.inv(self.jacobian)
            corners_xy = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]])
            w = corners_xy @ self.jacobian[1]
            wmin, wmax = w.min() - 1e-9, w.max() + 1e-9  # Eq. 4.11, on the (given) domain
            kmin = np.ceil((wmin - theta) / TWO_PI).astype(np.int64)
            nk = np.maximum(np.floor((wmax - theta) / TWO_PI).astype(np.int64) - kmin + 1, 0)
            idx = np.repeat(np.arange(len(q)), nk)  # one row per point and branching option k
            k = kmin[idx] + np.arange(len(idx)) - np.repeat(np.cumsum(nk) - nk, nk)
            xy = np.stack([rho[idx], theta[idx] + TWO_PI * k], axis=1) @ jinv.T  # Eq. 4.12
        if len(idx) == 0:
            return out
        inside = ((xy[:, 0] >= x0 - DOMAIN_TOL) & (xy[:, 0] <= x1 + DOMAIN_TOL)
                  & (xy[:, 1] >= y0 - DOMAIN_TOL) & (xy[:, 1] <= y1 + DOMAIN_TOL))
        xy = np.clip(xy, [x0, y0], [x1, y1])
        miss = np.linalg.norm(self.points(xy[:, 0], xy[:, 1]) - q[idx], axis=1)
        ok = inside & (miss <= tol * max(scale, 1e-300) + 1e-300)
        for n, (x, y), good in zip(idx, xy, ok):
            if good:
                out[n].append((float(x), float(y)))
        return out

    # ----- raise / project, bend / unbend, placement (§4.3.1–4.3.3) --------------------------------
    def _need_cone(self, what: str) -> None:
        if self.kind != "cone":
            raise PleError(f"{what}: a {self.kind} field has no apex (only cone fields can {what})")

    def raised(self, z: float) -> BeCOTSField:
        """Raise(z): the same field with corner A at height z = FA·T above the plane through
        F normal to T (§4.3.1); z = 0 is Project, giving the planar COTS."""
        self._need_cone("raise")
        z = float(z)
        if not math.isfinite(z):
            raise PleError(f"raise height {echo(z)} must be finite")
        return replace(self, a=self.apex + self.radial + z * self.axis)

    def projected(self) -> BeCOTSField:
        """Project: the closest projection onto the plane through F normal to T (§4.3.1)."""
        return self.raised(0.0)

    def unbent(self) -> BeCOTSField:
        """Unbend (Eq. 4.6): unroll the cone onto the plane through F and A (w = w' sin β)."""
        self._need_cone("unbend")
        sb = math.sin(self.beta)
        fa = self.a - self.apex
        h = np.cross(np.cross(fa, self.axis), fa)
        return replace(self, axis=unit(h), u=(self.u[0], self.u[1] * sb), v=(self.v[0], self.v[1] * sb))

    def bent(self, beta: float) -> BeCOTSField:
        """Bend (Eq. 4.5) the unbent COTS onto the cone of half-angle ``beta`` about F keeping F,
        A and the tangent plane along FA: T' = sin β T + cos β FA/|FA|, w' = w / sin β."""
        self._need_cone("bend")
        beta = float(beta)
        if not 0.0 < beta < math.pi:
            raise PleError(f"bend angle beta={echo(beta)}: must lie strictly between 0 and π")
        flat = self.unbent()
        sb = math.sin(beta)
        t = sb * flat.axis + math.cos(beta) * unit(self.a - self.apex)
        return replace(flat, axis=unit(t), u=(flat.u[0], flat.u[1] / sb), v=(flat.v[0], flat.v[1] / sb))

    def placed(self, g: Similarity) -> BeCOTSField:
        """The field moved by similarity G: G ∘ S(x, y) ∘ G⁻¹, map G ∘ M (§4.3.3 placement)."""
        m = g.matrix
        lin = m[:3, :3]
        move = lambda p: lin @ p + m[:3, 3]  # noqa: E731
        if self.kind == "translation":
            return replace(self, a=move(self.a), tu=lin @ self.tu, tv=lin @ self.tv)
        u, v = self.u, self.v
        if self.kind == "cylinder":  # slides scale with G
            u, v = (u[0] * g.factor, u[1]), (v[0] * g.factor, v[1])
        return replace(self, a=move(self.a), apex=move(self.apex), axis=unit(lin @ self.axis), u=u, v=v)

    def controls(self) -> dict:
        """Warp (ln m_u, w_u, ln m_v, w_v of the flat COTS), bend beta, and placement: the
        inputs of ``from_controls`` that rebuild this field (§4.3.3)."""
        self._need_cone("split into warp, bend and placement")
        flat = self.unbent()
        a = unit(self.a - self.apex)
        perp = self.axis - (self.axis @ a) * a
        b = unit(perp)
        s = float(np.linalg.norm(self.a - self.apex))
        frame = np.eye(4)
        frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = s * a, s * np.cross(b, a), s * b, self.apex
        return {"warp": (flat.u[0], flat.u[1], flat.v[0], flat.v[1]), "beta": self.beta,
                "placement": Similarity.from_matrix(frame, "placement")}

    # ----- patterns (§4.4) ----------------------------------------------------------------------
    def tile_corners(self, i: int, j: int, counts) -> np.ndarray:
        """The 4 corners of tile T[i, j] (image of the cell [i/nu, (i+1)/nu] × [j/nv, (j+1)/nv])."""
        nu, nv = counts
        x = np.array([i, i, i + 1, i + 1]) / nu
        y = np.array([j, j + 1, j + 1, j]) / nv
        return self.points(x, y)

    def pattern_total(self, counts, template_measure: float, power: int) -> float:
        """Sum of a measure of degree ``power`` (2: area, 3: volume) over the nu × nv pattern
        of a template shape, in O(1) by geometric series (§4.4.5, Eq. 4.13)."""
        nu, nv = counts
        total = float(template_measure)
        for m, n in zip(self.factors, (nu, nv)):
            d = m ** (power / n)  # ratio between consecutive shapes
            total *= geometric_sum(d, n)
        return total

    def pattern_area(self, counts, template_area: float) -> float:
        return self.pattern_total(counts, template_area, 2)

    def pattern_volume(self, counts, template_volume: float) -> float:
        return self.pattern_total(counts, template_volume, 3)

    # ----- IR ----------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Exact field parameters (used in IR when the corners cannot rebuild the field)."""
        if self.kind == "translation":
            return {"kind": self.kind, "a": self.a.tolist(), "tu": self.tu.tolist(), "tv": self.tv.tolist()}
        return {"kind": self.kind, "a": self.a.tolist(), "apex": self.apex.tolist(), "axis": self.axis.tolist(),
                "u": list(self.u), "v": list(self.v)}

    @staticmethod
    def from_dict(d: dict, where: str = "field") -> BeCOTSField:
        if not isinstance(d, dict) or d.get("kind") not in KINDS:
            raise PleError(f"{where}.kind: expected one of {', '.join(KINDS)}")
        try:
            if d["kind"] == "translation":
                fld = BeCOTSField("translation", as3(d["a"], f"{where}.a"), tu=as3(d["tu"], f"{where}.tu"),
                                  tv=as3(d["tv"], f"{where}.tv"))
            else:
                u, v = (tuple(float(x) for x in d[k]) for k in ("u", "v"))
                if len(u) != 2 or len(v) != 2 or not all(math.isfinite(x) for x in u + v):
                    raise PleError(f"{where}.u/v: expected two finite numbers each")
                axis = as3(d["axis"], f"{where}.axis")
                if np.linalg.norm(axis) < 1e-12:
                    raise PleError(f"{where}.axis: zero vector")
                fld = BeCOTSField(d["kind"], as3(d["a"], f"{where}.a"), as3(d["apex"], f"{where}.apex"),
                                  unit(axis), u, v)
        except KeyError as exc:
            raise PleError(f"{where}.{exc.args[0]}: missing") from None
        except (TypeError, ValueError):
            raise PleError(f"{where}: malformed field parameters") from None
        fld._check_map()
        return fld

    def branch_of_corners(self) -> tuple[int, int] | None:
        """(ku, kv) such that ``from_corners(*corners, branch)`` rebuilds this field, or None."""
        try:
            base = BeCOTSField.from_corners(*self.corners)
        except PleError:
            return None
        if base.kind != self.kind:
            return None
        if self.kind == "translation":
            return (0, 0)
        sign = 1.0 if base.axis @ self.axis > 0 else -1.0  # the rebuilt axis may point the other way
        ks = tuple(round((sign * mine[1] - theirs[1]) / TWO_PI)
                   for mine, theirs in ((self.u, base.u), (self.v, base.v)))
        try:
            again = BeCOTSField.from_corners(*self.corners, branch=ks)
        except PleError:
            return None
        same = all(again.similarity(x, y).allclose(self.similarity(x, y), 1e-8) for x, y in ((0.5, 0.5), (0.3, 0.9)))
        return tuple(ks) if same else None


def _branch(branch) -> tuple[int, int]:
    try:
        ku, kv = branch
    except (TypeError, ValueError):
        raise PleError(f"branch {echo(branch)}: expected two integers (ku, kv)") from None
    if any(isinstance(k, bool) or int(k) != k for k in (ku, kv)):
        raise PleError(f"branch {echo(branch)}: expected two integers (ku, kv)")
    return int(ku), int(kv)


def _axis_from_corners(A, B, C, D, sv) -> np.ndarray:
    """The common rotation axis direction T of U and V (Eq. 4.8)."""
    if sv[2] <= 1e-12 * sv[0]:  # special case: coplanar corners -> planar COTS, T = plane normal
        normal = np.cross(B - A, D - A)
        if np.linalg.norm(normal) < 1e-12 * sv[0] ** 2:
            normal = np.cross(B - A, C - A)
        return unit(normal)
    du = unit(B - A) - unit(C - D)  # U turns edge AB into DC: du ⟂ T
    dv = unit(D - A) - unit(C - B)  # V turns edge AD into BC: dv ⟂ T
    n = np.cross(du, dv)
    if np.linalg.norm(n) > PARALLEL_TOL:
        return unit(n)
    # (one of du, dv zero — a "pure dilation" U or V — puts F, A and the corners on one plane, so
    # that case was already taken by the coplanar special case above)
    if min(np.linalg.norm(du), np.linalg.norm(dv)) > PARALLEL_TOL:
        # special case "cylinder": du ∥ dv (e.g. two screws about one axis) leave a one-parameter
        # family of axes T ⟂ du; pick the one where U's and V's planar fixed points coincide
        axis = _axis_by_common_centre(A, B, C, D, unit(du))
        if axis is not None:
            return axis
    raise PleError("corners A, B, C, D: the rotation axis of U and V is undetermined (parallel edges)")


def _planar_centres(A, B, C, D, axis) -> tuple[complex, complex] | None:
    e1 = unit(np.cross(axis, [1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.cross(axis, [0.0, 1.0, 0.0]))
    e2 = np.cross(axis, e1)
    za, zb, zc, zd = (complex((p - A) @ e1, (p - A) @ e2) for p in (A, B, C, D))
    if min(abs(zb - za), abs(zd - za)) < 1e-12:
        return None
    qu, qv = (zc - zd) / (zb - za), (zc - zb) / (zd - za)
    if min(abs(qu - 1), abs(qv - 1)) < 1e-12:
        return None
    return (zd - qu * za) / (1 - qu), (zb - qv * za) / (1 - qv)


def _axis_by_common_centre(A, B, C, D, du) -> np.ndarray | None:
    """Axis T ⟂ du where U's and V's planar fixed points coincide. With equal opposite edges
    (|AB| = |DC|, |AD| = |BC|: two screws) a whole interval of axes fits the corners exactly;
    we then pick the one with the least total rotation |w_u| + |w_v| (the corners do not
    determine the field there)."""
    from scipy.optimize import minimize_scalar

    p = unit(np.cross(du, [1.0, 0.0, 0.0]) if abs(du[0]) < 0.9 else np.cross(du, [0.0, 1.0, 0.0]))
    q = np.cross(du, p)
    scale = max(np.linalg.norm(x - A) for x in (B, C, D))
    axis_of = lambda phi: np.cos(phi) * p + np.sin(phi) * q  # noqa: E731

    def miss(phi: float) -> float:
        c = _planar_centres(A, B, C, D, axis_of(phi))
        return np.inf if c is None else abs(c[0] - c[1]) / scale

    grid = np.linspace(0.0, math.pi, 361)
    misses = np.array([miss(g) for g in grid])
    fits = []
    for phi in grid[misses <= 1e-9]:
        try:
            fld = _field_with_axis(A, B, C, D, axis_of(phi), 0, 0)
        except PleError:
            continue
        if np.abs(fld.corners - np.array([A, B, C, D])).max() <= 1e-9 * scale:
            fits.append((abs(fld.u[1]) + abs(fld.v[1]), phi))
    if len(fits) > 1:  # special case: a family of fields fits; least rotation
        return axis_of(min(fits)[1])
    best = grid[int(np.argmin(misses))]
    res = minimize_scalar(miss, bounds=(best - math.pi / 360, best + math.pi / 360), method="bounded",
                          options={"xatol": 1e-14})
    if not res.fun <= 1e-9:
        return None
    return axis_of(res.x)


ANGLE_ROUNDING = 1e-14  # radians: a fitted rotation angle this small is the corners' rounding, not a turn


def _unrounded(angle: float) -> float:
    """``angle``, or exactly 0.0 within ``ANGLE_ROUNDING``."""
    return 0.0 if abs(angle) <= ANGLE_ROUNDING else angle


def _field_with_axis(A, B, C, D, axis, ku: int, kv: int) -> BeCOTSField:
    """U, V about axis T through a common fixed point, from the corners projected onto the
    plane through A normal to T (Eq. 4.9, planar spiral similarities of §2.4.6)."""
    e1 = unit(np.cross(axis, [1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.cross(axis, [0.0, 1.0, 0.0]))
    e2 = np.cross(axis, e1)
    z = {n: complex((p - A) @ e1, (p - A) @ e2) for n, p in zip("ABCD", (A, B, C, D))}
    h = {n: float((p - A) @ axis) for n, p in zip("ABCD", (A, B, C, D))}
    if abs(z["B"]) < 1e-12 * (abs(z["C"]) + abs(z["D"])) or abs(z["D"]) < 1e-12 * (abs(z["B"]) + abs(z["C"])):
        raise PleError("corners A, B, C, D: an edge from A is parallel to the field's axis (degenerate map)")
    qu = (z["C"] - z["D"]) / (z["B"] - z["A"])  # U takes A'B' to D'C'
    qv = (z["C"] - z["B"]) / (z["D"] - z["A"])  # V takes A'D' to B'C'
    lu, lv = math.log(abs(qu)), math.log(abs(qv))
    # an angle within rounding of the corners is none (edges AB ∥ DC give U a pure dilation, on any CPU)
    wu = _unrounded(math.atan2(qu.imag, qu.real)) + TWO_PI * ku
    wv = _unrounded(math.atan2(qv.imag, qv.real)) + TWO_PI * kv
    if abs(qu - 1) >= abs(qv - 1) and abs(qu - 1) > 1e-12:
        f = (z["D"] - qu * z["A"]) / (1 - qu)  # fixed point of U: F' = (D' - q A') / (1 - q)
    elif abs(qv - 1) > 1e-12:
        f = (z["B"] - qv * z["A"]) / (1 - qv)
    else:
        raise PleError("corners A, B, C, D admit no BeCOTS field (no rotation and no dilation, not a parallelogram)")
    apex_plane = A + f.real * e1 + f.imag * e2
    if max(abs(lu), abs(lv)) > NEAR_UNIT_FACTOR:
        # cone: h_A = FA·T from the dilation with the larger |ln m| (Eq. 4.9: h = AC·T / (m - 1))
        if abs(lu) >= abs(lv):
            ha = h["D"] / (math.exp(lu) - 1.0)
        else:
            ha = h["B"] / (math.exp(lv) - 1.0)
        fld = BeCOTSField("cone", A.copy(), apex_plane - ha * axis, axis, (lu, wu), (lv, wv))
    else:  # special case: no dilation at all -> two screws about one axis (a cylinder)
        fld = BeCOTSField("cylinder", A.copy(), apex_plane, axis, (h["D"], wu), (h["B"], wv))
    fld._check_map()
    return fld


# ===== BeCOTS slabs on lattices ===================================================================
@dataclass
class Stack:
    """BeCOTS stack (§6.3): ``layers`` copies of the template node-group, layer k shifted by
    ``k · step`` (a 3-vector: constant-distance raise along T, or normal offset at A)."""

    layers: int
    nodes_per_layer: int
    step: np.ndarray
    mode: str = "raise"

    def to_ir(self) -> dict:
        return {"layers": self.layers, "nodes_per_layer": self.nodes_per_layer, "step": self.step.tolist(),
                "mode": self.mode}


@dataclass
class BeCOTS:
    """What ``lat.becots`` holds: the field, repetition counts (nu, nv), ``closed`` and an
    optional stack description."""

    field: BeCOTSField
    counts: tuple[int, int]
    closed: bool = False
    stack: Stack | None = None

    @property
    def U(self) -> Similarity:  # noqa: N802 - incremental U of the lattice
        return self.field.similarity(1.0 / self.counts[0], 0.0)

    @property
    def V(self) -> Similarity:  # noqa: N802
        return self.field.similarity(0.0, 1.0 / self.counts[1])

    @property
    def group_counts(self) -> tuple[int, int]:
        extra = 1 if self.closed else 0
        return self.counts[0] + extra, self.counts[1] + extra

    def to_ir(self) -> dict:
        out: dict = {}
        branch = self.field.branch_of_corners()
        if branch is None:
            out["field"] = self.field.to_dict()
        else:
            out["corners"] = self.field.corners.tolist()
            if branch != (0, 0):
                out["branch"] = list(branch)
        out["counts"] = list(self.counts)
        if self.closed:
            out["closed"] = True
        if self.stack is not None:
            out["stack"] = self.stack.to_ir()
        return out


def becots_counts(counts) -> tuple[int, int]:
    try:
        nu, nv = counts
    except (TypeError, ValueError):
        raise PleError(f"becots counts {echo(counts)}: expected two integers (nu, nv)") from None
    for name, n in (("nu", nu), ("nv", nv)):
        if isinstance(n, bool) or int(n) != n or int(n) < 1:
            raise PleError(f"becots counts: {name} must be an integer >= 1, got {echo(n)}")
    return int(nu), int(nv)


def becots_of(lat) -> BeCOTS:
    """``lat.becots``, checked against the lattice's U and V (a later set_u/set_v breaks it)."""
    info = lat.becots
    if not isinstance(info, BeCOTS):
        raise PleError("the lattice is not a BeCOTS slab (call set_becots)")
    if (lat.u.count, lat.v.count) != info.group_counts or not (
            lat.U.allclose(info.U, 1e-9) and lat.V.allclose(info.V, 1e-9)):
        raise PleError("the lattice's U or V was changed after set_becots: it is no longer a BeCOTS slab")
    return info
