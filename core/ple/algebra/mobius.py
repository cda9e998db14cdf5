"""Planar Möbius transformations and cline inversions (thesis §11.1–11.2).

A Möbius transformation ``z -> (a z + b) / (c z + d)`` of the extended complex plane is held
as its complex 2x2 matrix normalized to ``ad - bc = 1`` (§11.1.2). It is built from its
complex form, from a Möbius frame {A, B, C} = {G(0), G(1), G(i)} (§11.1.3), from three point
pairs, or as an even composition of cline inversions (§11.1.1). Real powers ``U**t`` follow
§11.2.3: a circle inversion R centred on a fixed point of U conjugates U into a similarity
S = R ∘ U ∘ R, whose real power (``Similarity.power_matrices``, Eq. 2.8–2.9) is conjugated
back, ``U**t = R ∘ S**t ∘ R``.

In 3D a planar Möbius transformation acts by its Poincaré extension (the same even number
of inversions, in spheres centred on the plane z = 0): spheres go to spheres, so a ball maps
to a ball exactly (``map_balls``), which is what makes Möbius lattices' nodes rectified.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

import numpy as np

from ..errors import PleError, echo
from .similarity import Similarity, Translation
from .vectors import Vec

EPS = 1e-13  # relative size below which c counts as 0 (a similarity) or two points coincide


def as_complex(p) -> complex:
    """A point given as complex, (x, y) or (x, y, z) (z ignored) as a complex number."""
    if isinstance(p, (complex, float, int, np.number)) and not isinstance(p, bool):
        z = complex(p)
    else:
        q = np.asarray(p, dtype=float).reshape(-1)
        if q.shape not in ((2,), (3,)):
            raise PleError(f"point {echo(p)}: expected a complex number or 2D/3D coordinates")
        z = complex(q[0], q[1])
    if not (math.isfinite(z.real) and math.isfinite(z.imag)):
        raise PleError(f"point {echo(p)} is not finite")
    return z


def _normalized(m: np.ndarray) -> np.ndarray:
    """Divide (..., 2, 2) complex matrices by sqrt(det) so that ad - bc = 1 (§11.1.2)."""
    det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    if np.any(np.abs(det) == 0):
        raise PleError("Möbius transformation with ad - bc = 0 (degenerate)")
    return m / np.sqrt(det)[..., None, None]


@dataclass(frozen=True, eq=False)
class Mobius:
    """A planar Möbius transformation, matrix ``m`` = [[a, b], [c, d]] with ad - bc = 1."""

    m: np.ndarray
    split: tuple | None = None  # (S, M_R) when built as R ∘ S ∘ R: powers conjugate S's (§11.2.3)

    # ----- constructors -----------------------------------------------------------------------
    @staticmethod
    def from_coefficients(a, b, c, d) -> Mobius:
        """The complex form ``(a z + b) / (c z + d)`` (§11.1.2), normalized."""
        m = np.array([[a, b], [c, d]], dtype=complex)
        if not np.all(np.isfinite(m)):
            raise PleError("Möbius coefficients must be finite")
        det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        if abs(det) <= EPS * max(1.0, float(np.abs(m).max()) ** 2):
            raise PleError("Möbius coefficients with ad - bc = 0 define no transformation")
        return Mobius(_normalized(m))

    @staticmethod
    def identity() -> Mobius:
        return Mobius(np.eye(2, dtype=complex))

    @staticmethod
    def from_similarity(s: Similarity) -> Mobius:
        """A planar similarity (rotation axis along z) as ``z -> alpha z + beta``."""
        mat = s.matrix
        if np.abs(mat[2, :3] - [0, 0, mat[2, 2]]).max() > 1e-12 or abs(mat[2, 3]) > 1e-12:
            raise PleError("similarity is not planar (it must keep the plane z = 0)")
        return Mobius.from_coefficients(complex(mat[0, 0], mat[1, 0]), complex(mat[0, 3], mat[1, 3]), 0, 1)

    @staticmethod
    def conjugated(s: Similarity, inversion: Cline) -> Mobius:
        """``R ∘ S ∘ R`` for a planar similarity S and a cline inversion R (§11.2.1); its real
        powers are ``R ∘ S**t ∘ R`` with S's own angle (beyond ±π when S says so)."""
        mr = inversion.antiholomorphic()
        m = Mobius.from_similarity(s).m
        return Mobius(_normalized(mr @ m.conj() @ mr.conj()), (s, mr))

    @staticmethod
    def _to_standard(z0: complex, z1: complex, zinf: complex) -> np.ndarray:
        """Matrix of F(z0, z1, z∞) taking z0 -> 0, z1 -> 1, z∞ -> ∞ (Eq. 11.2)."""
        pts = (z0, z1, zinf)
        scale = max(1.0, max(abs(p) for p in pts))
        for x in range(3):
            for y in range(x + 1, 3):
                if abs(pts[x] - pts[y]) <= 1e-12 * scale:
                    raise PleError("Möbius frame: its three points must be distinct")
        return np.array([[z1 - zinf, -z0 * (z1 - zinf)], [z1 - z0, -zinf * (z1 - z0)]], dtype=complex)

    @staticmethod
    def from_points(src, dst) -> Mobius:
        """The Möbius transformation taking three distinct points ``src`` to ``dst`` (Eq. 11.3)."""
        if len(src) != 3 or len(dst) != 3:
            raise PleError("Möbius from points: expected three source and three target points")
        fs = Mobius._to_standard(*(as_complex(p) for p in src))
        fd = Mobius._to_standard(*(as_complex(p) for p in dst))
        return Mobius(_normalized(np.linalg.inv(fd) @ fs))

    @staticmethod
    def from_frame(a, b, c) -> Mobius:
        """The transformation G of the Möbius frame {A, B, C}: G(0,0)=A, G(1,0)=B, G(0,1)=C (§11.1.3)."""
        return Mobius.from_points((0, 1, 1j), (a, b, c))

    @staticmethod
    def between_frames(frame0, frame1) -> Mobius:
        """The Möbius transformation taking frame {A0, B0, C0} to {A1, B1, C1} (§11.1.3)."""
        return Mobius.from_points(frame0, frame1)

    # ----- form ---------------------------------------------------------------------------------
    @property
    def coefficients(self) -> tuple[complex, complex, complex, complex]:
        return (complex(self.m[0, 0]), complex(self.m[0, 1]), complex(self.m[1, 0]), complex(self.m[1, 1]))

    def frame(self) -> tuple[complex, complex, complex]:
        """The frame form {G(0), G(1), G(i)} (§11.1.3); a point may be ∞ (complex inf)."""
        return tuple(complex(x) for x in self(np.array([0, 1, 1j])))

    @property
    def is_similarity(self) -> bool:
        """c = 0: ∞ is fixed and the map is ``z -> alpha z + beta`` (§11.1.2)."""
        a, b, c, d = self.coefficients
        return abs(c) <= EPS * max(abs(a), abs(b), abs(d), 1.0)

    def fixed_points(self) -> tuple[complex, complex]:
        """The two fixed points (a - d ± sqrt((d - a)^2 + 4bc)) / 2c (§11.1.2); ∞ is complex inf."""
        a, b, c, d = self.coefficients
        if self.is_similarity:
            alpha = a / d
            if abs(alpha - 1) <= EPS:
                return (complex(math.inf, 0), complex(math.inf, 0))
            return ((b / d) / (1 - alpha), complex(math.inf, 0))
        root = cmath.sqrt((d - a) ** 2 + 4 * b * c)
        # the root without cancellation first, the other by Vieta (F1 F2 = -b/c): the fixed point
        # nearer the origin comes first and is accurate even when the other is huge
        big = (a - d + root) if abs(a - d + root) >= abs(a - d - root) else (a - d - root)
        if abs(big) <= EPS * max(abs(a), abs(d), 1.0):  # a = d and bc = 0: parabolic at 0
            return (0j, 0j)
        far = big / (2 * c)
        near = (-b / c) / far
        return (near, far)

    def to_similarity(self) -> Similarity:
        """This transformation as a planar Similarity (only when ``is_similarity``)."""
        if not self.is_similarity:
            raise PleError("this Möbius transformation is not a similarity (it moves ∞)")
        a, b, _, d = self.coefficients
        alpha, beta = a / d, b / d
        if abs(alpha - 1) <= 1e-15:
            return Translation(Vec(beta.real, beta.imag, 0.0))
        f = beta / (1 - alpha)
        return Similarity(abs(alpha), cmath.phase(alpha), (0.0, 0.0, 1.0), (f.real, f.imag, 0.0), 0.0)

    # ----- algebra ------------------------------------------------------------------------------
    def __matmul__(self, other: Mobius) -> Mobius:
        """Composition ``self ∘ other`` (Eq. 11.1)."""
        return Mobius(_normalized(self.m @ other.m))

    def inverse(self) -> Mobius:
        """``(-d z + b) / (c z - a)`` up to sign (§11.1.2)."""
        a, b, c, d = self.coefficients
        return Mobius(np.array([[d, -b], [-c, a]], dtype=complex))

    def allclose(self, other: Mobius, tol: float = 1e-9) -> bool:
        """Equal as transformations (matrices equal up to the sign left by normalization)."""
        x, y = self.m, other.m
        return bool(min(np.abs(x - y).max(), np.abs(x + y).max()) <= tol * max(1.0, float(np.abs(x).max())))

    def __call__(self, z):
        """Images of complex points (array); ∞ -> a/c and -d/c -> ∞ (complex inf)."""
        z = np.asarray(z, dtype=complex)
        a, b, c, d = self.coefficients
        inf = np.isinf(z)
        zz = np.where(inf, 0, z)
        num, den = a * zz + b, c * zz + d
        with np.errstate(divide="ignore", invalid="ignore"):
            out = num / den
        out = np.where(den == 0, complex(math.inf, 0), out)
        at_inf = complex(math.inf, 0) if c == 0 else a / c
        return np.where(inf, at_inf, out)

    def _conjugator(self) -> np.ndarray | None:
        """Matrix M_R of a unit circle inversion R = M_R ∘ conj centred on a fixed point of U
        (§11.2.1); None when U is already a similarity."""
        if self.is_similarity:
            return None
        f = self.fixed_points()[0]
        # R(z) = F + ρ² / conj(z - F) = M_R(conj z), M_R(w) = (F w + ρ² - |F|²) / (w - conj F); the
        # radius ρ² = |F|² + 1 keeps M_R = [[F, 1], [1, -conj F]] well conditioned for any F
        return np.array([[f, 1], [1, -f.conjugate()]], dtype=complex)

    def similarity_part(self) -> tuple[Similarity, np.ndarray | None]:
        """(S, M_R): S = R ∘ U ∘ R as a Similarity and the inversion's matrix (None if U is one)."""
        if self.split is not None:
            return self.split
        mr = self._conjugator()
        if mr is None:
            return self.to_similarity(), None
        s = _normalized(mr @ self.m.conj() @ mr.conj())  # R∘U∘R = M_R Ū M̄_R fixes ∞ (c is rounding)
        return Mobius(np.array([[s[0, 0], s[0, 1]], [0, s[1, 1]]], dtype=complex)).to_similarity(), mr

    def power_matrices(self, ts) -> np.ndarray:
        """Normalized matrices of ``U**t`` for every real t in ``ts``, shape (n, 2, 2) (§11.2.3).
        Near a parabolic U (its two fixed points merging: the conjugation to a similarity loses
        about half the digits), integer powers are products of U's own matrix instead (by
        squaring), which keep them."""
        ts = np.asarray(ts, dtype=float).reshape(-1)
        if not np.all(np.isfinite(ts)):
            raise PleError("Möbius power must be finite")
        if self.near_parabolic() and np.all(ts == np.round(ts)) and np.all(np.abs(ts) <= 1 << 30):
            return _normalized(np.stack([_integer_power(self.m, int(t)) for t in ts]))
        s, mr = self.similarity_part()
        sm = s.power_matrices(ts)
        st = np.zeros((len(ts), 2, 2), dtype=complex)
        st[:, 0, 0] = sm[:, 0, 0] + 1j * sm[:, 1, 0]
        st[:, 0, 1] = sm[:, 0, 3] + 1j * sm[:, 1, 3]
        st[:, 1, 1] = 1.0
        if mr is not None:
            st = mr[None] @ st.conj() @ mr.conj()[None]  # U^t = R ∘ S^t ∘ R
        return _normalized(st)

    def near_parabolic(self) -> bool:
        """Whether U's fixed points nearly merge, (a + d)² within ``PARABOLIC`` of 4 (ad - bc = 1),
        while U is no similarity (those power exactly)."""
        a, _, _, d = self.coefficients
        return not self.is_similarity and abs((a + d) ** 2 - 4) <= PARABOLIC

    def __pow__(self, t: float) -> Mobius:
        split = None if self.split is None else (self.split[0] ** float(t), self.split[1])
        return Mobius(self.power_matrices([float(t)])[0], split)

    # ----- 3D action (Poincaré extension) ---------------------------------------------------------
    def apply_points(self, pts) -> np.ndarray:
        """Images of 3D points (..., 3): the plane z = 0 maps by the complex form; above and
        below it by the Poincaré extension (height t -> t / (|cz+d|^2 + |c|^2 t^2))."""
        return apply_matrices(self.m, pts)

    def map_balls(self, centers, radii) -> tuple[np.ndarray, np.ndarray]:
        """Images of balls (centres (N, 3), radii (N,)): balls again (spheres go to spheres)."""
        c = np.asarray(centers, dtype=float).reshape(-1, 3)
        m = np.broadcast_to(self.m, (len(c), 2, 2))
        return map_balls(m, c, np.asarray(radii, dtype=float).reshape(-1))

    def __repr__(self) -> str:
        a, b, c, d = (complex(round(x.real, 9), round(x.imag, 9)) for x in self.coefficients)
        return f"Mobius(a={a}, b={b}, c={c}, d={d})"


PARABOLIC = 1e-6  # |(a + d)² - 4| below which the fixed points' conjugation loses too many digits


def _integer_power(m: np.ndarray, n: int) -> np.ndarray:
    """m**n for a 2×2 matrix of determinant 1, by squaring (n < 0: of its inverse)."""
    if n < 0:
        m, n = np.array([[m[1, 1], -m[0, 1]], [-m[1, 0], m[0, 0]]], dtype=complex), -n
    out = np.eye(2, dtype=complex)
    while n:
        if n & 1:
            out = out @ m
        m = m @ m
        n >>= 1
    return out


def apply_matrices(m: np.ndarray, pts) -> np.ndarray:
    """Poincaré extension of normalized Möbius matrices m (N or broadcast, 2, 2) on points (N, 3)."""
    p = np.asarray(pts, dtype=float)
    shape = p.shape
    p = p.reshape(-1, 3)
    m = np.broadcast_to(m, (len(p), 2, 2))
    a, b, c, d = m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1]
    z, t = p[:, 0] + 1j * p[:, 1], p[:, 2]
    den = np.abs(c * z + d) ** 2 + np.abs(c) ** 2 * t * t
    if np.any(den <= 0):
        raise PleError("a point maps to infinity under the Möbius transformation")
    zz = ((a * z + b) * np.conj(c * z + d) + a * np.conj(c) * t * t) / den
    return np.stack([zz.real, zz.imag, t / den], axis=1).reshape(shape)


def map_balls(m: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Balls (centres (N, 3), radii (N,)) under normalized Möbius matrices m (N, 2, 2), exactly:
    M = T(a/c) ∘ (z -> -z / c^2) ∘ (inversion, then reflection) ∘ T(d/c), or a similarity if c = 0."""
    a, b, c, d = m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1]
    z, t, r = centers[:, 0] + 1j * centers[:, 1], centers[:, 2].astype(float), radii.astype(float)
    sim = np.abs(c) <= EPS * np.maximum(1.0, np.maximum(np.abs(a), np.abs(d)))
    out_z, out_t, out_r = np.empty_like(z), np.empty_like(t), np.empty_like(r)
    if sim.any():
        k = a[sim] / d[sim]
        out_z[sim] = k * z[sim] + b[sim] / d[sim]
        out_t[sim], out_r[sim] = np.abs(k) * t[sim], np.abs(k) * r[sim]
    g = ~sim
    if g.any():
        cg = c[g]
        z1 = z[g] + d[g] / cg  # 1. translate the pole -d/c to 0
        den = np.abs(z1) ** 2 + t[g] ** 2 - r[g] ** 2
        if np.any(den <= 1e-12 * np.maximum(r[g], 1e-300) ** 2):
            raise PleError("a node ball contains (or touches) the Möbius pole; its image is not a ball")
        z2, t2, r2 = np.conj(z1) / den, t[g] / den, r[g] / den  # 2. inversion + reflection (1/z)
        k = -1.0 / cg**2  # 3. z -> -z / c^2
        out_z[g] = k * z2 + a[g] / cg  # 4. translate by a/c
        out_t[g], out_r[g] = np.abs(k) * t2, np.abs(k) * r2
    return np.stack([out_z.real, out_z.imag, out_t], axis=1), out_r


@dataclass(frozen=True)
class Cline:
    """A circle (centre, radius > 0) or a line (point, direction) of the plane (§11.1.1)."""

    center: complex = 0j
    radius: float = 1.0
    line: bool = False
    direction: complex = 1 + 0j

    @staticmethod
    def circle(center, radius: float) -> Cline:
        r = float(radius)
        if not (math.isfinite(r) and r > 0):
            raise PleError(f"circle radius must be positive, got {echo(radius)}")
        return Cline(as_complex(center), r)

    @staticmethod
    def through(p, q) -> Cline:
        """The line through two distinct points."""
        a, b = as_complex(p), as_complex(q)
        if abs(b - a) == 0:
            raise PleError("line: the two points coincide")
        return Cline(a, 0.0, True, (b - a) / abs(b - a))

    def invert(self, z):
        """Images of complex points under the inversion (reflection for a line); the centre
        goes to ∞ and ∞ to the centre."""
        z = np.asarray(z, dtype=complex)
        if self.line:
            u = self.direction
            return np.where(np.isinf(z), z, self.center + u * np.conj((z - self.center) / u))
        w = z - self.center
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self.center + self.radius**2 / np.conj(w)
        out = np.where(w == 0, complex(math.inf, 0), out)
        return np.where(np.isinf(z), self.center, out)

    def antiholomorphic(self) -> np.ndarray:
        """Matrix M with ``inversion(z) = M(conj z)`` (a Möbius matrix, not normalized)."""
        o, r = self.center, self.radius
        if self.line:
            u2 = self.direction**2
            return np.array([[u2, o - u2 * o.conjugate()], [0, 1]], dtype=complex)
        return np.array([[o, r * r - abs(o) ** 2], [1, -o.conjugate()]], dtype=complex)

    def __matmul__(self, other: Cline) -> Mobius:
        """The Möbius transformation ``self ∘ other`` (two inversions, §11.1.1)."""
        return Mobius(_normalized(self.antiholomorphic() @ other.antiholomorphic().conj()))


def mobius_frame(frame0, frame1, u: float):
    """MöbiusFrame({A0,B0,C0}, {A1,B1,C1}, u) (Eq. 11.5): the frame G**u ∘ frame0, with G
    taking frame0 to frame1; u = i gives P[i] of the steady pattern (Eq. 11.4)."""
    g = Mobius.between_frames(frame0, frame1)
    return tuple(complex(x) for x in (g ** u)(np.array([as_complex(p) for p in frame0])))
