"""Orientation-preserving 3D similarities in canonical form (thesis §2.4–2.5).

Every similarity is stored canonically as

    x  ->  P + s R(alpha, r) (x - P) + d r

with factor ``s > 0``, rotation ``alpha`` about the unit axis ``r`` through the point
``P`` and a slide ``d`` along that axis. A *screw* has ``s == 1`` (Eq. 2.6), a *swirl*
has ``s != 1`` and ``d == 0`` (Eq. 2.7). Real powers follow Eq. 2.8–2.9:
``S**t`` has factor ``s**t``, angle ``t alpha`` and slide ``t d``; the angle is kept as
given (beyond 2π when a program says so), which a 4x4 matrix cannot express.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import PleError, echo
from .vectors import Pt, Vec, as3, rotation_matrices, unit

# Below these the rotation axis (or the swirl's fixed point) is numerically meaningless:
# the similarity is treated as its degenerate kind (pure translation / screw), see §2.5.5.
NEAR_ZERO_ANGLE = 1e-10
NEAR_UNIT_FACTOR = 1e-12
SIMILARITY_TOL = 1e-6  # allowed deviation of R^T R from I for a matrix to count as a similarity

KINDS = ("identity", "translation", "rotation", "scaling", "screw", "swirl")


@dataclass(frozen=True)
class Similarity:
    """A canonical similarity; build it with the constructors below, not directly."""

    factor: float = 1.0
    angle: float = 0.0
    axis: tuple = (0.0, 0.0, 1.0)
    point: tuple = (0.0, 0.0, 0.0)
    distance: float = 0.0

    # ----- classification -------------------------------------------------------------
    @property
    def kind(self) -> str:
        """One of identity, translation, rotation, scaling, screw, swirl (§2.5.1)."""
        rotates = self.angle != 0.0
        if self.factor != 1.0:
            return "swirl" if rotates else "scaling"
        if rotates:
            return "screw" if self.distance != 0.0 else "rotation"
        return "translation" if self.distance != 0.0 else "identity"

    @property
    def r(self) -> np.ndarray:
        return np.array(self.axis, dtype=float)

    @property
    def p(self) -> np.ndarray:
        return np.array(self.point, dtype=float)

    # ----- matrices -----------------------------------------------------------------------
    @property
    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous matrix (column vectors: ``M @ [x, 1]``)."""
        return self.power_matrices(np.array([1.0]))[0]

    def power_matrices(self, ts) -> np.ndarray:
        """Matrices of ``S**t`` for every t in ``ts`` (Eq. 2.8–2.9), shape (n, 4, 4)."""
        ts = np.asarray(ts, dtype=float).reshape(-1)
        r, p = self.r, self.p
        lin = rotation_matrices(r, ts * self.angle) * (self.factor ** ts)[:, None, None]
        out = np.zeros((len(ts), 4, 4))
        out[:, :3, :3] = lin
        # translation part (I - s^t R^t) P + t d r
        out[:, :3, 3] = p[None] - lin @ p + (ts * self.distance)[:, None] * r[None]
        out[:, 3, 3] = 1.0
        return out

    # ----- algebra -------------------------------------------------------------------------
    def __pow__(self, t: float) -> Similarity:
        t = float(t)
        if not math.isfinite(t):
            raise PleError(f"similarity power must be finite, got {t}")
        return Similarity(self.factor ** t, self.angle * t, self.axis, self.point, self.distance * t)

    def inverse(self) -> Similarity:
        return self ** -1.0

    def __matmul__(self, other: Similarity) -> Similarity:
        """Composition ``self ∘ other`` (apply ``other`` first), canonicalized."""
        return Similarity.from_matrix(self.matrix @ other.matrix)

    def apply_points(self, pts) -> np.ndarray:
        """Images of points, array (..., 3)."""
        m = self.matrix
        pts = np.asarray(pts, dtype=float)
        return pts @ m[:3, :3].T + m[:3, 3]

    def apply_vectors(self, vecs) -> np.ndarray:
        """Images of free vectors (linear part only), array (..., 3)."""
        return np.asarray(vecs, dtype=float) @ self.matrix[:3, :3].T

    def apply_balls(self, centers, radii):
        """Images of balls: (centres (..., 3), radii (...)); radii scale by the factor."""
        return self.apply_points(centers), np.asarray(radii, dtype=float) * self.factor

    def allclose(self, other: Similarity, tol: float = 1e-9) -> bool:
        """Equal as transformations (matrices within ``tol``, relative to their size)."""
        a, b = self.matrix, other.matrix
        scale = max(1.0, float(np.abs(a).max()), float(np.abs(b).max()))
        return bool(np.abs(a - b).max() <= tol * scale)

    # ----- conversions -------------------------------------------------------------------
    @staticmethod
    def from_matrix(matrix, what: str = "matrix") -> Similarity:
        """Canonical screw or swirl of any orientation-preserving similarity matrix."""
        m = np.asarray(matrix, dtype=float)
        if m.shape != (4, 4):
            raise PleError(f"{what}: expected a 4x4 matrix, got shape {m.shape}")
        if not np.all(np.isfinite(m)):
            raise PleError(f"{what}: entries must be finite")
        if np.abs(m[3] - [0, 0, 0, 1]).max() > 1e-12:
            raise PleError(f"{what}: last row must be [0, 0, 0, 1]")
        a, b = m[:3, :3], m[:3, 3]
        det = float(np.linalg.det(a))
        if det <= 0:
            raise PleError(f"{what}: not an orientation-preserving similarity (determinant {det:.3g})")
        s = det ** (1.0 / 3.0)
        rot = a / s
        if np.abs(rot.T @ rot - np.eye(3)).max() > SIMILARITY_TOL:
            raise PleError(f"{what}: not a similarity (the linear part is not a scaled rotation)")
        axis, angle = _axis_angle(rot)
        if abs(s - 1.0) <= NEAR_UNIT_FACTOR:
            return _screw_from(axis, angle, b)
        # swirl / pure dilation: the unique fixed point solves (I - A) P = b (s != 1)
        try:
            fixed = np.linalg.solve(np.eye(3) - a, b)
        except np.linalg.LinAlgError:  # s within float noise of 1 (e.g. a float32 rotation matrix)
            return _screw_from(axis, angle, b)
        if angle == 0.0:
            axis = np.array([0.0, 0.0, 1.0])
        return Similarity(s, angle, tuple(axis), tuple(fixed), 0.0)

    @staticmethod
    def between_frames(frame_a, frame_b, names: tuple = ("frame A", "frame B")) -> Similarity:
        """The similarity taking 3D frame A onto frame B (§2.5.5).

        A frame is a 4x4 matrix whose columns are X, Y, Z, O (|X| = |Y| = |Z|, orthogonal,
        right-handed) or a tuple (O, X, Y, Z). The result maps O_A to O_B and each axis
        vector of A to that of B; it is ``B · A⁻¹`` decomposed canonically. ``names``: how an
        error names the two frames.
        """
        fa, fb = _frame_matrix(frame_a, names[0]), _frame_matrix(frame_b, names[1])
        return Similarity.from_matrix(fb @ np.linalg.inv(fa), "similarity between frames")

    @staticmethod
    def from_point_pairs(a, b, c, d) -> Similarity:
        """The planar similarity taking the pair {A, B} to {C, D} (§2.4.6, Eq. 2.5).

        Points are 2D (x, y) or 3D with equal z (the plane z = const); the result is a
        translation when AB = CD, else a spiral (swirl about the z axis through F).
        """
        pts = [np.asarray(q, dtype=float).reshape(-1) for q in (a, b, c, d)]
        z = pts[0][2] if pts[0].shape == (3,) else 0.0
        for q in pts:
            if q.shape not in ((2,), (3,)) or not np.all(np.isfinite(q)):
                raise PleError("point pair: points must be finite 2D or 3D coordinates")
            if q.shape == (3,) and abs(q[2] - z) > 1e-12:
                raise PleError("point pair: 3D points must lie in one plane z = const")
        za, zb, zc, zd = (complex(q[0], q[1]) for q in pts)
        if abs(zb - za) < 1e-15:
            raise PleError("point pair: A and B coincide")
        if abs(zd - zc) < 1e-15:
            raise PleError("point pair: C and D coincide")
        if abs((zb - za) - (zd - zc)) < 1e-15:  # AB == CD: pure translation
            t = zc - za
            return Translation(Vec(t.real, t.imag, 0.0))
        # Spiral(alpha, s, F): z -> F + q (z - F) with q = CD / AB; F = (C - qA) / (1 - q)
        q = (zd - zc) / (zb - za)
        if abs(q - 1) < 1e-15:
            t = zc - za
            return Translation(Vec(t.real, t.imag, 0.0))
        f = (zc - q * za) / (1 - q)
        return Similarity(abs(q), math.atan2(q.imag, q.real), (0.0, 0.0, 1.0), (f.real, f.imag, z), 0.0)

    def to_dict(self) -> dict:
        """The IR form ``{"kind": ..., ...}`` with the argument names of SPEC §5."""
        k = self.kind
        ax, pt = list(self.axis), list(self.point)
        if k == "identity":
            return {"kind": k}
        if k == "translation":
            return {"kind": k, "vector": list(self.distance * self.r)}
        if k == "rotation":
            return {"kind": k, "angle": self.angle, "axis": ax, "point": pt}
        if k == "scaling":
            return {"kind": k, "factor": self.factor, "point": pt}
        if k == "screw":
            return {"kind": k, "angle": self.angle, "axis": ax, "point": pt, "distance": self.distance}
        return {"kind": k, "angle": self.angle, "axis": ax, "point": pt, "factor": self.factor}

    def to_code(self, digits: int = 6) -> str:
        """Program code for this similarity, e.g. ``Swirl(0.224, Vec(0, 1, 0), Pt(10.872, 0, 0.039), 0.953)``."""

        def num(x: float) -> str:
            v = round(float(x), digits)
            return repr(0.0 if v == 0 else v).removesuffix(".0") if v == int(v) else repr(v)

        def tri(name: str, v) -> str:
            return f"{name}({', '.join(num(c) for c in v)})"

        k, d = self.kind, self.to_dict()
        if k == "identity":
            return "Identity()"
        if k == "translation":
            return f"Translation({tri('Vec', d['vector'])})"
        if k == "scaling":
            return f"Scaling({num(self.factor)}, {tri('Pt', self.point)})"
        head = f"{num(self.angle)}, {tri('Vec', self.axis)}, {tri('Pt', self.point)}"
        if k == "rotation":
            return f"Rotation({head})"
        if k == "screw":
            return f"Screw({head}, {num(self.distance)})"
        return f"Swirl({head}, {num(self.factor)})"

    def __repr__(self) -> str:
        return self.to_code(12)


def _axis_angle(rot: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis and angle in [0, π] of a rotation matrix (Rodrigues inverted)."""
    w = 0.5 * np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
    sin_a = float(np.linalg.norm(w))
    cos_a = float(np.clip((np.trace(rot) - 1.0) / 2.0, -1.0, 1.0))
    angle = math.atan2(sin_a, cos_a)
    if angle <= NEAR_ZERO_ANGLE:  # near-degenerate axis: no usable rotation
        return np.array([0.0, 0.0, 1.0]), 0.0
    if sin_a > 1e-6 or cos_a > 0:  # small or ordinary angles: the skew part gives the axis
        return w / sin_a, angle
    # half turn (sin ≈ 0, cos ≈ -1): R + I = 2 r r^T, read r off its largest column
    sym = (rot + np.eye(3)) / 2.0
    col = sym[:, int(np.argmax(np.diag(sym)))]
    axis = col / np.linalg.norm(col)
    # fix the sign so that the skew part (if any) agrees with sin(angle) r
    if float(w @ axis) < 0:
        axis = -axis
    return axis, angle


def _screw_from(axis: np.ndarray, angle: float, b: np.ndarray) -> Similarity:
    """Canonical screw of x -> R x + b (s == 1), Eq. 2.6."""
    if angle == 0.0:  # pure translation (or identity)
        n = float(np.linalg.norm(b))
        if n <= 1e-15:
            return Similarity()
        return Similarity(1.0, 0.0, tuple(b / n), (0.0, 0.0, 0.0), n)
    d = float(b @ axis)
    b_perp = b - d * axis
    if abs(d) <= NEAR_UNIT_FACTOR * max(1.0, float(np.linalg.norm(b))):  # round-off slide: a pure rotation
        d = 0.0
    # the axis point closest to the origin: P = (b⊥ + cot(α/2) r × b⊥) / 2
    point = 0.5 * (b_perp + np.cross(axis, b_perp) / math.tan(angle / 2.0))
    return Similarity(1.0, angle, tuple(axis), tuple(point), d)


def _frame_matrix(frame, what: str) -> np.ndarray:
    if isinstance(frame, (tuple, list)) and len(frame) == 4:
        o, x, y, z = (as3(v, what) for v in frame)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, o
    else:
        m = np.asarray(frame, dtype=float)
        if m.shape != (4, 4):
            raise PleError(f"{what}: expected (O, X, Y, Z) or a 4x4 matrix")
    lin = m[:3, :3]
    n = np.linalg.norm(lin, axis=0)
    if n.min() < 1e-12:
        raise PleError(f"{what}: axis vectors must be non-zero")
    ortho = np.abs((lin / n).T @ (lin / n) - np.eye(3)).max()
    if np.abs(n / n[0] - 1).max() > SIMILARITY_TOL or ortho > SIMILARITY_TOL:
        raise PleError(f"{what}: X, Y, Z must be orthogonal and of equal length")
    if np.linalg.det(lin) <= 0:
        raise PleError(f"{what}: X, Y, Z must be right-handed")
    return m


# ----- constructors with the argument orders of SPEC §4 -----------------------------------
def Identity() -> Similarity:  # noqa: N802
    return Similarity()


def Translation(vec) -> Similarity:  # noqa: N802
    v = Vec(vec)
    scale = float(np.abs(v).max())
    if scale == 0.0:
        return Similarity()
    n = scale * float(np.linalg.norm(v / scale))  # scaled first: |(1e200, 0, 0)|² would overflow
    if not math.isfinite(n):
        raise PleError(f"translation vector {list(v)} is too long")
    return Similarity(1.0, 0.0, tuple(v / n), (0.0, 0.0, 0.0), n)


def _angle(angle) -> float:
    a = float(angle)
    if not math.isfinite(a):
        raise PleError(f"angle must be finite, got {echo(angle)}")
    return a


def _factor(factor) -> float:
    s = float(factor)
    if not math.isfinite(s) or s <= 0:
        raise PleError(f"scaling factor must be a positive number, got {echo(factor)}")
    return s


def Rotation(angle, axis, point) -> Similarity:  # noqa: N802
    return Similarity(1.0, _angle(angle), tuple(unit(axis, "rotation axis")), tuple(Pt(point)), 0.0)


def Scaling(factor, point) -> Similarity:  # noqa: N802
    return Similarity(_factor(factor), 0.0, (0.0, 0.0, 1.0), tuple(Pt(point)), 0.0)


def Swirl(angle, axis, point, factor) -> Similarity:  # noqa: N802
    return Similarity(_factor(factor), _angle(angle), tuple(unit(axis, "swirl axis")), tuple(Pt(point)), 0.0)


def Screw(angle, axis, point, distance) -> Similarity:  # noqa: N802
    d = float(distance)
    if not math.isfinite(d):
        raise PleError(f"screw distance must be finite, got {echo(distance)}")
    return Similarity(1.0, _angle(angle), tuple(unit(axis, "screw axis")), tuple(Pt(point)), d)


def similarity_from_dict(d: dict, where: str = "similarity") -> Similarity:
    """Parse the IR form ``{"kind": ..., ...}``; errors name the offending field."""
    if not isinstance(d, dict):
        raise PleError(f"{where}: expected an object with a 'kind'")
    kind = d.get("kind")
    need = {
        "identity": (),
        "translation": ("vector",),
        "rotation": ("angle", "axis", "point"),
        "scaling": ("factor", "point"),
        "swirl": ("angle", "axis", "point", "factor"),
        "screw": ("angle", "axis", "point", "distance"),
    }
    if kind not in need:
        raise PleError(f"{where}.kind: unknown kind {echo(kind)} (expected one of {', '.join(need)})")
    args = []
    for name in need[kind]:
        if name not in d:
            raise PleError(f"{where}.{name}: missing for kind {echo(kind)}")
        args.append(d[name])
    build = {"identity": Identity, "translation": Translation, "rotation": Rotation,
             "scaling": Scaling, "swirl": Swirl, "screw": Screw}[kind]
    try:
        return build(*args)
    except (PleError, TypeError, ValueError) as exc:
        raise PleError(f"{where}: {exc}") from None


def commute(a: Similarity, b: Similarity) -> bool:
    """Do ``a`` and ``b`` commute (a ∘ b == b ∘ a, to 1e-10 relative to their matrices)? Steady
    rows along two directions are similar copies of each other exactly when they do (thesis §7.3.1)."""
    ma, mb = a.matrix, b.matrix
    scale = max(1.0, np.abs(ma).max(), np.abs(mb).max()) ** 2
    return bool(np.abs(ma @ mb - mb @ ma).max() <= 1e-10 * scale)

