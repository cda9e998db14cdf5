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

from .errors import PleError
from .geometry import _as3
from .lattice import Lattice
from .similarity import Similarity, Translation

TWO_PI = 2.0 * math.pi
NEAR_UNIT_FACTOR = 1e-12  # |ln m| below this: no dilation (m == 1), the cylinder/translation kinds
PARALLEL_TOL = 1e-9  # unit-vector differences below this: the edges are parallel (no rotation)
CORNER_TOL = 1e-7  # relative miss of a rebuilt corner above which the corners admit no field
DOMAIN_TOL = 1e-9  # slack on the unit square when inverting
KINDS = ("cone", "cylinder", "translation")


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _rotate(v: np.ndarray, axis: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rodrigues: rotate vectors v (n, 3) about unit ``axis`` by ``angles`` (n,)."""
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x, y, z = axis
    cross = np.stack([y * v[:, 2] - z * v[:, 1], z * v[:, 0] - x * v[:, 2], x * v[:, 1] - y * v[:, 0]], axis=1)
    return v * c + cross * s + axis * (v @ axis)[:, None] * (1.0 - c)


# ===== fields ===================================================================================
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
        pts = [_as3(p, f"corner {n}") for p, n in zip((a, b, c, d), "ABCD")]
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
            raise PleError(f"warp {warp!r}: values must be finite")
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
        e1 = _unit(self.radial)
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
        fa = _unit(self.a - self.apex)
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
            raise PleError(f"raise height {z!r} must be finite")
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
        return replace(self, axis=_unit(h), u=(self.u[0], self.u[1] * sb), v=(self.v[0], self.v[1] * sb))

    def bent(self, beta: float) -> BeCOTSField:
        """Bend (Eq. 4.5) the unbent COTS onto the cone of half-angle ``beta`` about F keeping F,
        A and the tangent plane along FA: T' = sin β T + cos β FA/|FA|, w' = w / sin β."""
        self._need_cone("bend")
        beta = float(beta)
        if not 0.0 < beta < math.pi:
            raise PleError(f"bend angle beta={beta!r}: must lie strictly between 0 and π")
        flat = self.unbent()
        sb = math.sin(beta)
        t = sb * flat.axis + math.cos(beta) * _unit(self.a - self.apex)
        return replace(flat, axis=_unit(t), u=(flat.u[0], flat.u[1] / sb), v=(flat.v[0], flat.v[1] / sb))

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
        return replace(self, a=move(self.a), apex=move(self.apex), axis=_unit(lin @ self.axis), u=u, v=v)

    def controls(self) -> dict:
        """Warp (ln m_u, w_u, ln m_v, w_v of the flat COTS), bend beta, and placement: the
        inputs of ``from_controls`` that rebuild this field (§4.3.3)."""
        self._need_cone("split into warp, bend and placement")
        flat = self.unbent()
        a = _unit(self.a - self.apex)
        perp = self.axis - (self.axis @ a) * a
        b = _unit(perp)
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
            total *= n if abs(d - 1.0) <= 1e-15 else (d**n - 1.0) / (d - 1.0)
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
                fld = BeCOTSField("translation", _as3(d["a"], f"{where}.a"), tu=_as3(d["tu"], f"{where}.tu"),
                                  tv=_as3(d["tv"], f"{where}.tv"))
            else:
                u, v = (tuple(float(x) for x in d[k]) for k in ("u", "v"))
                if len(u) != 2 or len(v) != 2 or not all(math.isfinite(x) for x in u + v):
                    raise PleError(f"{where}.u/v: expected two finite numbers each")
                axis = _as3(d["axis"], f"{where}.axis")
                if np.linalg.norm(axis) < 1e-12:
                    raise PleError(f"{where}.axis: zero vector")
                fld = BeCOTSField(d["kind"], _as3(d["a"], f"{where}.a"), _as3(d["apex"], f"{where}.apex"),
                                  _unit(axis), u, v)
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
        raise PleError(f"branch {branch!r}: expected two integers (ku, kv)") from None
    if any(isinstance(k, bool) or int(k) != k for k in (ku, kv)):
        raise PleError(f"branch {branch!r}: expected two integers (ku, kv)")
    return int(ku), int(kv)


def _axis_from_corners(A, B, C, D, sv) -> np.ndarray:
    """The common rotation axis direction T of U and V (Eq. 4.8)."""
    if sv[2] <= 1e-12 * sv[0]:  # special case: coplanar corners -> planar COTS, T = plane normal
        normal = np.cross(B - A, D - A)
        if np.linalg.norm(normal) < 1e-12 * sv[0] ** 2:
            normal = np.cross(B - A, C - A)
        return _unit(normal)
    du = _unit(B - A) - _unit(C - D)  # U turns edge AB into DC: du ⟂ T
    dv = _unit(D - A) - _unit(C - B)  # V turns edge AD into BC: dv ⟂ T
    n = np.cross(du, dv)
    if np.linalg.norm(n) > PARALLEL_TOL:
        return _unit(n)
    # (one of du, dv zero — a "pure dilation" U or V — puts F, A and the corners on one plane, so
    # that case was already taken by the coplanar special case above)
    if min(np.linalg.norm(du), np.linalg.norm(dv)) > PARALLEL_TOL:
        # special case "cylinder": du ∥ dv (e.g. two screws about one axis) leave a one-parameter
        # family of axes T ⟂ du; pick the one where U's and V's planar fixed points coincide
        axis = _axis_by_common_centre(A, B, C, D, _unit(du))
        if axis is not None:
            return axis
    raise PleError("corners A, B, C, D: the rotation axis of U and V is undetermined (parallel edges)")


def _planar_centres(A, B, C, D, axis) -> tuple[complex, complex] | None:
    e1 = _unit(np.cross(axis, [1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.cross(axis, [0.0, 1.0, 0.0]))
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

    p = _unit(np.cross(du, [1.0, 0.0, 0.0]) if abs(du[0]) < 0.9 else np.cross(du, [0.0, 1.0, 0.0]))
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


def _field_with_axis(A, B, C, D, axis, ku: int, kv: int) -> BeCOTSField:
    """U, V about axis T through a common fixed point, from the corners projected onto the
    plane through A normal to T (Eq. 4.9, planar spiral similarities of §2.4.6)."""
    e1 = _unit(np.cross(axis, [1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.cross(axis, [0.0, 1.0, 0.0]))
    e2 = np.cross(axis, e1)
    z = {n: complex((p - A) @ e1, (p - A) @ e2) for n, p in zip("ABCD", (A, B, C, D))}
    h = {n: float((p - A) @ axis) for n, p in zip("ABCD", (A, B, C, D))}
    if abs(z["B"]) < 1e-12 * (abs(z["C"]) + abs(z["D"])) or abs(z["D"]) < 1e-12 * (abs(z["B"]) + abs(z["C"])):
        raise PleError("corners A, B, C, D: an edge from A is parallel to the field's axis (degenerate map)")
    qu = (z["C"] - z["D"]) / (z["B"] - z["A"])  # U takes A'B' to D'C'
    qv = (z["C"] - z["B"]) / (z["D"] - z["A"])  # V takes A'D' to B'C'
    lu, lv = math.log(abs(qu)), math.log(abs(qv))
    wu = math.atan2(qu.imag, qu.real) + TWO_PI * ku
    wv = math.atan2(qv.imag, qv.real) + TWO_PI * kv
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


def _counts(counts) -> tuple[int, int]:
    try:
        nu, nv = counts
    except (TypeError, ValueError):
        raise PleError(f"becots counts {counts!r}: expected two integers (nu, nv)") from None
    for name, n in (("nu", nu), ("nv", nv)):
        if isinstance(n, bool) or int(n) != n or int(n) < 1:
            raise PleError(f"becots counts: {name} must be an integer >= 1, got {n!r}")
    return int(nu), int(nv)


def set_field(lat: Lattice, fld: BeCOTSField, counts=(1, 1), closed: bool = False, stack: Stack | None = None) -> None:
    """Make ``lat`` a BeCOTS slab of field ``fld``: node-group (i, j) = S(i/nu, j/nv) ∘ template."""
    nu, nv = _counts(counts)
    info = BeCOTS(fld, (nu, nv), bool(closed), stack)
    gu, gv = info.group_counts
    lat.set_u(gu, info.U)
    lat.set_v(gv, info.V)
    lat.becots = info


def set_becots(lat: Lattice, a, b, c, d, counts=(1, 1), branch=(0, 0), closed: bool = False) -> None:
    """``lat.set_becots(A, B, C, D, counts=(nu, nv))``: U and V from the corner-operated field."""
    set_field(lat, BeCOTSField.from_corners(a, b, c, d, branch), counts, closed)


def becots_from_ir(lat: Lattice, data, where: str = "becots") -> None:
    """Apply the IR ``"becots"`` object (SPEC §5) to ``lat``; errors name the offending field."""
    if not isinstance(data, dict):
        raise PleError(f"{where}: expected an object with corners and counts")
    unknown = sorted(set(data) - {"corners", "counts", "branch", "closed", "field", "stack"})
    if unknown:
        raise PleError(f"{where}.{unknown[0]}: unknown field")
    if ("corners" in data) == ("field" in data):
        raise PleError(f"{where}: give exactly one of 'corners' or 'field'")
    if "counts" not in data:
        raise PleError(f"{where}.counts: missing")
    counts = data["counts"]
    if not isinstance(counts, list) or len(counts) != 2 or any(isinstance(n, bool) or not isinstance(n, int)
                                                               for n in counts):
        raise PleError(f"{where}.counts: expected two integers [nu, nv], got {counts!r}")
    closed = data.get("closed", False)
    if not isinstance(closed, bool):
        raise PleError(f"{where}.closed: expected true or false")
    try:
        if "corners" in data:
            corners = data["corners"]
            if not isinstance(corners, list) or len(corners) != 4:
                raise PleError(f"{where}.corners: expected 4 points [A, B, C, D]")
            pts = [_ir_point(p, f"{where}.corners[{n}]") for n, p in enumerate(corners)]
            fld = BeCOTSField.from_corners(*pts, branch=data.get("branch", (0, 0)))
        else:
            fld = BeCOTSField.from_dict(data["field"], f"{where}.field")
        stack = _stack_from_ir(data["stack"], lat, f"{where}.stack") if "stack" in data else None
        set_field(lat, fld, counts, closed, stack)
    except PleError as exc:
        msg = str(exc)
        raise PleError(msg if msg.startswith(where) else f"{where}: {msg}") from None


def _ir_point(p, where: str) -> np.ndarray:
    if not isinstance(p, list) or len(p) != 3 or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in p):
        raise PleError(f"{where}: expected 3 numbers, got {p!r}")
    return _as3(p, where)


def _stack_from_ir(d, lat: Lattice, where: str) -> Stack:
    if not isinstance(d, dict):
        raise PleError(f"{where}: expected an object")
    try:
        layers, per = int(d["layers"]), int(d["nodes_per_layer"])
        step = _as3(d["step"], f"{where}.step")
    except KeyError as exc:
        raise PleError(f"{where}.{exc.args[0]}: missing") from None
    except (TypeError, ValueError):
        raise PleError(f"{where}: layers and nodes_per_layer must be integers") from None
    if layers < 1 or per < 1 or layers * per != len(lat.nodes):
        raise PleError(f"{where}: {layers} layers × {per} nodes do not match the {len(lat.nodes)} template nodes")
    return Stack(layers, per, step, str(d.get("mode", "raise")))


def becots_of(lat: Lattice) -> BeCOTS:
    """``lat.becots``, checked against the lattice's U and V (a later set_u/set_v breaks it)."""
    info = lat.becots
    if not isinstance(info, BeCOTS):
        raise PleError("the lattice is not a BeCOTS slab (call set_becots)")
    if (lat.u.count, lat.v.count) != info.group_counts or not (
            lat.U.allclose(info.U, 1e-9) and lat.V.allclose(info.V, 1e-9)):
        raise PleError("the lattice's U or V was changed after set_becots: it is no longer a BeCOTS slab")
    return info


# ===== lattices: connectivities, multi-level filter, stacks ======================================
CONNECTIVITIES = {
    # name: (template node positions in cell units, beams (n1, n2, di, dj)), Fig. 4.13
    "triangle": ([(0.0, 0.0)], [(0, 0, 1, 0), (0, 0, 0, 1), (0, 0, 1, 1)]),
    "kagome": ([(0.0, 0.0), (0.5, 0.0), (0.0, 0.5)],
               [(0, 1, 0, 0), (1, 2, 0, 0), (2, 0, 0, 0), (1, 0, 1, 0), (2, 0, 0, 1), (1, 2, 1, -1)]),
    "honeycomb": ([(0.0, 0.0), (1.0 / 3.0, 1.0 / 3.0)], [(0, 1, 0, 0), (1, 0, 1, 0), (1, 0, 0, 1)]),
}


def becots_lattice(fld: BeCOTSField, counts, connectivity: str = "triangle", radius: float = 0.05,
                   period: int = 1, keep=None, closed: bool = False) -> Lattice:
    """A BeCOTS lattice (§4.5, Fig. 4.13) of a named connectivity over field ``fld``.

    Nodes sit at field images of their cell positions, radius ``radius`` × the template
    cell size. ``period`` p > 1 builds the filtered multi-level variant (§4.5.1): the
    template node-group is a p × p block of cells (counts are in fine cells and must be
    multiples of p) and ``keep(a, b, n1, n2, da, db)`` — fine cell (a, b) in the block, fine
    offset (da, db) — decides which fine beams stay (default: keep one diagonal beam
    (da = db = 1) per p × p block, the one of its last cell, and every other beam)."""
    if connectivity not in CONNECTIVITIES:
        raise PleError(f"connectivity {connectivity!r}: expected one of {', '.join(CONNECTIVITIES)}")
    nu, nv = _counts(counts)
    p = int(period)
    if p < 1 or nu % p or nv % p:
        raise PleError(f"period {period!r}: must be >= 1 and divide the counts ({nu}, {nv})")
    if keep is None:
        keep = (lambda a, b, n1, n2, da, db: not (da == 1 and db == 1) or (a == p - 1 and b == p - 1)) \
            if p > 1 else (lambda *args: True)
    cells, beams = CONNECTIVITIES[connectivity]
    lat = Lattice()
    cell = float(np.linalg.norm(fld.points([0.0], [0.0]) - fld.points([1.0 / nu], [0.0])))
    ids = {}
    for a in range(p):
        for b in range(p):
            for n, (cx, cy) in enumerate(cells):
                pos = fld.points([(a + cx) / nu], [(b + cy) / nv])[0]
                ids[a, b, n] = lat.add_node(pos, radius * cell, f"n{n}_{a}_{b}" if p > 1 else f"n{n}")
    for a in range(p):
        for b in range(p):
            for n1, n2, da, db in beams:
                if not keep(a, b, n1, n2, da, db):
                    continue
                ta, tb = a + da, b + db  # fine target cell, possibly in a neighbouring block
                bi, bj = ta // p, tb // p
                lat.add_beam(ids[a, b, n1], ids[ta % p, tb % p, n2], bi, bj, 0)
    set_field(lat, fld, (nu // p, nv // p), closed)
    return lat


def stack_lattice(fld: BeCOTSField, counts, layers: int, spacing: float, mode: str = "raise",
                  connectivity: str = "triangle", radius: float = 0.05, links=((0, 0, 0, 0),)) -> Lattice:
    """BeCOTS stack (§6.3): ``layers`` layers sharing field S, layer k with corner
    A_k = A + k·spacing·e, e = T (constant-distance raise) or the cone normal at A (normal
    offset); ``links`` (n1, n2, di, dj) join node n1 of layer k to node n2 of layer k+1.

    Stored as one BeCOTS slab whose template node-group holds every layer (node id
    ``layer * nodes_per_layer + n``), so every command works unchanged."""
    if mode not in ("raise", "normal"):
        raise PleError(f"stack mode {mode!r}: expected raise or normal")
    if fld.kind == "translation":
        direction = _unit(np.cross(fld.tu, fld.tv))
    elif mode == "raise":
        direction = fld.axis
    else:  # normal of the cone at A: the part of T perpendicular to the generator FA
        fa = _unit(fld.a - fld.apex)
        direction = _unit(fld.axis - (fld.axis @ fa) * fa)
    layers = int(layers)
    if layers < 1:
        raise PleError(f"stack layers must be >= 1, got {layers}")
    base = becots_lattice(fld, counts, connectivity, radius)
    step = float(spacing) * direction
    nn = len(base.nodes)
    lat = Lattice()
    for k in range(layers):
        for node in base.nodes:
            lat.add_node(node.center + k * step, node.radius, f"{node.name}_L{k}")
    for k in range(layers):
        for bm in base.beams:
            lat.add_beam(k * nn + bm.n1, k * nn + bm.n2, bm.di, bm.dj, 0)
        if k + 1 < layers:
            for n1, n2, di, dj in links:
                lat.add_beam(k * nn + n1, (k + 1) * nn + n2, di, dj, 0)
    set_field(lat, fld, _counts(counts), False, Stack(layers, nn, step, mode))
    return lat


def stack_layer_coordinate(lat: Lattice, pts) -> np.ndarray:
    """Continuous layer coordinate t of points (n, 3): the two nearest layers of a point are
    floor(t) and floor(t) + 1 (§6.3: rotate about the axis into the plane of the line L of
    corners A_k, then project from F onto L)."""
    info = becots_of(lat)
    if info.stack is None:
        raise PleError("the lattice is not a BeCOTS stack")
    fld, step = info.field.placed(lat.placement), lat.placement.apply_vectors(info.stack.step)
    q = np.asarray(pts, float).reshape(-1, 3)
    a = fld.a
    if fld.kind == "translation":
        return (q - a) @ step / (step @ step)
    _, theta = fld.log_polar(q)
    back = fld.apex + _rotate(q - fld.apex, fld.axis, -theta)  # into the half-plane of A (and of L)
    if fld.kind == "cylinder":  # no apex: the nearest point of L in that half-plane
        return (back - a) @ step / (step @ step)
    # central projection from F onto L: F + s (back - F) = A + t step, solved by crossing with d
    d = back - fld.apex
    fa = a - fld.apex
    sd = np.cross(step, d)
    den = np.einsum("ij,ij->i", sd, sd)
    t = -np.einsum("ij,ij->i", np.cross(fa, d), sd) / np.where(den > 0, den, 1.0)
    return np.where(den > 0, t, 0.0)


def stack_pmc(lat: Lattice, pts) -> np.ndarray:
    """Point membership on a BeCOTS stack in O(1) per point (§6.3): test only the two
    nearest layers and the beams between them (through the BeCOTS RangeFinder)."""
    from .becots_rangefinder import query_subset

    info = becots_of(lat)
    q = np.asarray(pts, float).reshape(-1, 3)
    t = stack_layer_coordinate(lat, q)
    st = info.stack
    lower = np.clip(np.floor(np.nan_to_num(t)), 0, max(st.layers - 2, 0)).astype(np.int64)
    per, nn = st.nodes_per_layer, len(lat.nodes)
    # per pair (lo, lo + 1) of nearest layers: its nodes and the beam-patterns among them, as
    # positions in the shape list (nodes, then beams); short lists are padded by repetition
    lists = []
    for lo in range(max(st.layers - 1, 1)):
        near = {lo, min(lo + 1, st.layers - 1)}
        lists.append([k * per + x for k in sorted(near) for x in range(per)]
                     + [nn + p for p, b in enumerate(lat.beams) if b.n1 // per in near and b.n2 // per in near])
    width = max(len(x) for x in lists)
    table = np.array([x + [x[0]] * (width - len(x)) for x in lists], dtype=np.int64)
    res = query_subset(lat, q, np.zeros(len(q)), select=table[lower])
    return np.array([len(x.nodes) > 0 or len(x.beams) > 0 for x in res], dtype=bool)


# ===== constant-radius lattices and connectors (§4.5.3) ==========================================
@dataclass
class ConnectorClass:
    """Connectors of one node-pattern with the same set of incident beam-pattern ends:
    ``points`` the descriptor points of the template connector (k, 3), ``mesh`` its
    connector mesh (``connector_mesh``), ``instances`` (m, 4, 4) rigid motions taking it onto each connector, ``nodes``
    (m, 4) their node indices."""

    key: tuple
    points: np.ndarray
    mesh: object
    instances: np.ndarray
    nodes: np.ndarray


def _fibonacci_sphere(n: int) -> np.ndarray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = math.pi * (1 + 5**0.5) * k
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _local_frame(dirs: np.ndarray) -> np.ndarray:
    """Orthonormal frame (columns x, y, z) of a connector, from its first two non-parallel
    incident beam directions only: congruent configurations get congruent frames."""
    e0 = dirs[0] if len(dirs) else np.array([0.0, 0.0, 1.0])
    other = next((d for d in dirs[1:] if np.linalg.norm(np.cross(d, e0)) > 1e-6), None)
    if other is None:
        other = np.array([1.0, 0.0, 0.0]) if abs(e0[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = _unit(other - (other @ e0) * e0)
    return np.stack([x, np.cross(e0, x), e0], axis=1)


def _ring_basis(d: np.ndarray, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ux = frame[:, 0] - (frame[:, 0] @ d) * d
    ux = _unit(ux) if np.linalg.norm(ux) > 1e-6 else _unit(np.cross(d, frame[:, 1]))
    return ux, np.cross(d, ux)


def connector_points(center, directions, radius: float, beam_radius: float, grow: float = 0.5,
                     samples: int = 32) -> np.ndarray:
    """Descriptor points of a connector (for alignment): a sphere of radius (1 + grow)·radius
    around the node and, per incident beam direction (k, 3), a ring of radius
    beam_radius·(1 + grow) at distance (1 + 2 grow)·radius along it, in the local frame."""
    dirs = np.asarray(directions, float).reshape(-1, 3)
    frame = _local_frame(dirs)
    pts = [np.asarray(center, float) + (1 + grow) * radius * (_fibonacci_sphere(samples) @ frame.T)]
    ang = np.linspace(0, TWO_PI, 12, endpoint=False)
    for d in dirs:
        ux, uy = _ring_basis(d, frame)
        ring = np.cos(ang)[:, None] * ux + np.sin(ang)[:, None] * uy
        pts.append(center + (1 + 2 * grow) * radius * d + beam_radius * (1 + grow) * ring)
    return np.concatenate(pts)


def connector_mesh(center, directions, radius: float, beam_radius: float, grow: float = 0.5, segments: int = 32):
    """The connector of §4.5.3 as a trimesh: (grown hub ∩ enlarged node) − hub, where the hub
    is the node ball (radius) with rods (beam_radius) along the incident beam directions, the
    grown hub uses radii × (1 + grow) and the enlarged node has radius (1 + 2 grow)·radius.
    Built in the local frame with manifold3d Booleans, then placed."""
    import trimesh
    from manifold3d import Manifold

    dirs = np.asarray(directions, float).reshape(-1, 3)
    frame = _local_frame(dirs)
    outer = (1 + 2 * grow) * radius
    length = 2.0 * outer

    def rods(rad: float) -> list:
        out = []
        for d in dirs:
            ux, uy = _ring_basis(d, frame)
            rot = frame.T @ np.stack([ux, uy, d], axis=1)  # local z -> local direction of d
            m = np.hstack([rot, np.zeros((3, 1))])
            out.append(Manifold.cylinder(length, rad, rad, segments).transform(m))
        return out

    grown = Manifold.batch_boolean([Manifold.sphere((1 + grow) * radius, segments), *rods(beam_radius * (1 + grow))],
                                   _op("Add"))
    hub = Manifold.batch_boolean([Manifold.sphere(radius, segments), *rods(beam_radius)], _op("Add"))
    conn = (grown ^ Manifold.sphere(outer, segments)) - hub
    mesh = conn.to_mesh()
    verts = np.asarray(mesh.vert_properties, float)[:, :3] @ frame.T + np.asarray(center, float)
    return trimesh.Trimesh(verts, np.asarray(mesh.tri_verts), process=False)


def _op(name: str):
    from manifold3d import OpType

    return getattr(OpType, name)


def kabsch(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Best rigid motion (4x4, rotation + translation) taking point set p onto q (n, 3)."""
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    h = (p - pc).T @ (q - qc)
    uu, _, vt = np.linalg.svd(h)
    dd = np.sign(np.linalg.det(vt.T @ uu.T))
    rot = vt.T @ np.diag([1.0, 1.0, dd]) @ uu.T
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, qc - rot @ pc
    return m


def constant_radius_connectors(lat: Lattice, radius: float, beam_radius: float | None = None,
                               grow: float = 0.5, region=None) -> tuple[list[ConnectorClass], dict]:
    """Constant-radius version of a BeCOTS lattice (§4.5.3): every node gets ``radius`` and
    every beam ``beam_radius`` (rods); connectors grouped into classes by node-pattern and
    set of incident beam-pattern ends. Returns the classes and the beams
    (``{"start": (m, 3), "end": (m, 3), "radius": r}``)."""

    becots_of(lat)
    radius = float(radius)
    beam_radius = radius * 0.5 if beam_radius is None else float(beam_radius)
    if not (radius > 0 and 0 < beam_radius <= radius):
        raise PleError(f"constant radius {radius!r} / beam radius {beam_radius!r}: need 0 < beam radius <= radius")
    ev = lat.evaluate(region)
    centers = ev.center
    ends: list[list[tuple]] = [[] for _ in range(len(centers))]
    for p, (s, e) in zip(ev.beam_index[:, 3], ev.beam_nodes):
        ends[s].append((int(p), 0, e))
        ends[e].append((int(p), 1, s))
    classes: dict[tuple, list[int]] = {}
    for row, inc in enumerate(ends):
        key = (int(ev.node_index[row, 3]), tuple(sorted((p, end) for p, end, _ in inc)))
        classes.setdefault(key, []).append(row)
    out = []
    for key, rows in classes.items():
        gen = []
        for row in rows:
            inc = sorted(ends[row])
            dirs = np.array([_unit(centers[other] - centers[row]) for _, _, other in inc]).reshape(-1, 3)
            gen.append(connector_points(centers[row], dirs, radius, beam_radius, grow))
        template = gen[0]
        motions = np.array([kabsch(template, g) for g in gen])
        row = rows[0]
        dirs = np.array([_unit(centers[other] - centers[row]) for _, _, other in sorted(ends[row])]).reshape(-1, 3)
        mesh = connector_mesh(centers[row], dirs, radius, beam_radius, grow)
        out.append(ConnectorClass(key, template, mesh, motions, ev.node_index[rows]))
    beams = {"start": centers[ev.beam_nodes[:, 0]], "end": centers[ev.beam_nodes[:, 1]], "radius": beam_radius}
    return out, beams


def export_connectors(lat: Lattice, folder, radius: float, beam_radius: float | None = None,
                      grow: float = 0.5, region=None) -> dict:
    """Write one mesh per connector class (``connector_<n>.stl``), the beams as constant-
    radius cylinders (``beams.stl``) and ``connectors.json`` (class keys, instance motions)."""
    import json
    from pathlib import Path

    import trimesh

    from .files import atomic_path, atomic_write_text, check_output_dir, write_marker

    folder = Path(folder)
    check_output_dir(folder, "ple-connectors")  # ours, new or empty: never another folder's files
    classes, beams = constant_radius_connectors(lat, radius, beam_radius, grow, region)
    folder.mkdir(exist_ok=True)
    write_marker(folder, "ple-connectors", "ple becots connectors")
    summary = {"classes": [], "beams": len(beams["start"]), "radius": radius, "beam_radius": beams["radius"]}
    for n, cls in enumerate(classes):
        path = folder / f"connector_{n}.stl"
        with atomic_path(path) as tmp:
            cls.mesh.export(tmp, file_type="stl")
        summary["classes"].append({"file": path.name, "node": cls.key[0], "ends": [list(e) for e in cls.key[1]],
                                   "count": len(cls.instances), "nodes": cls.nodes.tolist(),
                                   "motions": cls.instances.round(12).tolist()})
    cyl = []
    for a, b in zip(beams["start"], beams["end"]):
        if np.linalg.norm(b - a) > 1e-12:
            cyl.append(trimesh.creation.cylinder(radius=beams["radius"], segment=np.stack([a, b]), sections=12))
    if cyl:
        with atomic_path(folder / "beams.stl") as tmp:
            trimesh.util.concatenate(cyl).export(tmp, file_type="stl")
    atomic_write_text(folder / "connectors.json", json.dumps(summary) + "\n")
    return summary


__all__ = ["BeCOTS", "BeCOTSField", "Stack", "becots_from_ir", "becots_lattice", "becots_of",
           "constant_radius_connectors", "export_connectors", "set_becots", "set_field", "stack_lattice",
           "stack_pmc"]
