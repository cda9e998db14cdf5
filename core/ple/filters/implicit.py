"""Implicit-field filters (thesis §9, Fig. 9.4) and tetrahedrally symmetric Fourier fields (004_ §3.1–3.2).

A field maps world points to values; a node survives where the field at its centre is below
the level (``network``: f < level) or where |f| < level (``sheet``: a shell around the surface
f = 0). Fields live in cell coordinates: ``x_cell = G⁻¹(x) / cell`` for a placement similarity
G and a cell size, so a field repeats with period ``cell`` (a TPMS of period 2π in its own
variables, a Fourier field of period 1 on the unit cube [-0.5, 0.5)³).
"""

from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod

import numpy as np

from ..algebra.similarity import Similarity
from ..errors import PleError, echo
from .base import Filter

EVAL_CHUNK = 1 << 12  # points per vectorized Fourier evaluation (small chunks stay in cache: measured best)
VARIANTS = ("network", "sheet")


def _td_operators() -> np.ndarray:
    """The 24 operators of T_d (004_ §3.1, App. A.1) as 3x3 matrices: the symmetries of the
    tetrahedron with vertices (1,1,1), (1,-1,-1), (-1,1,-1), (-1,-1,1) are the 6 axis
    permutations times the 4 sign flips with an even number of minus signs."""
    ops = []
    for perm in itertools.permutations(range(3)):
        for signs in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)):
            q = np.zeros((3, 3))
            q[range(3), perm] = signs
            ops.append(q)
    return np.array(ops)


TD_OPERATORS = _td_operators()


class Field(ABC):
    """A scalar field on world points, through a placement similarity and a cell size."""

    def __init__(self, cell=1.0, placement: Similarity | None = None) -> None:
        cell = np.asarray(cell, dtype=float)
        if cell.shape not in ((), (3,)) or not np.all(np.isfinite(cell)) or np.any(cell <= 0):
            raise PleError(f"field cell size must be a positive number (or three), got {echo(cell)}")
        if placement is not None and not isinstance(placement, Similarity):
            raise PleError("field placement must be a Similarity")
        self.cell = cell
        self.placement = placement or Similarity()

    def local(self, points) -> np.ndarray:
        """Cell coordinates (N, 3) of world points: G⁻¹(x) / cell."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return self.placement.inverse().apply_points(p) / self.cell

    def __call__(self, points) -> np.ndarray:
        return self.evaluate_local(self.local(points))

    @abstractmethod
    def evaluate_local(self, x: np.ndarray) -> np.ndarray:
        """Field values (N,) at cell coordinates x (N, 3)."""


# ----- triply periodic minimal surface approximations (level sets in 2π-periodic variables) -------
def _gyroid(x, y, z):
    return np.sin(x) * np.cos(y) + np.sin(y) * np.cos(z) + np.sin(z) * np.cos(x)


def _schwarz_p(x, y, z):
    return np.cos(x) + np.cos(y) + np.cos(z)


def _schwarz_d(x, y, z):
    sx, sy, sz, cx, cy, cz = np.sin(x), np.sin(y), np.sin(z), np.cos(x), np.cos(y), np.cos(z)
    return sx * sy * sz + sx * cy * cz + cx * sy * cz + cx * cy * sz


def _diamond(x, y, z):
    # the D surface in its other common form (shifted by a quarter cell from schwarz_d)
    return np.cos(x) * np.cos(y) * np.cos(z) - np.sin(x) * np.sin(y) * np.sin(z)


def _iwp(x, y, z):
    cx, cy, cz = np.cos(x), np.cos(y), np.cos(z)
    return 2 * (cx * cy + cy * cz + cz * cx) - (np.cos(2 * x) + np.cos(2 * y) + np.cos(2 * z))


TPMS = {"gyroid": _gyroid, "schwarz_p": _schwarz_p, "schwarz_d": _schwarz_d, "diamond": _diamond, "iwp": _iwp}


class TPMSField(Field):
    """Gyroid, Schwarz P, Schwarz D, diamond or I-WP, with period ``cell``."""

    def __init__(self, kind: str, cell=1.0, placement: Similarity | None = None) -> None:
        if kind not in TPMS:
            raise PleError(f"unknown implicit field {echo(kind)}; known: {', '.join(TPMS)}, fourier")
        super().__init__(cell, placement)
        self.kind = kind

    def evaluate_local(self, x):
        t = 2 * math.pi * x
        return TPMS[self.kind](t[:, 0], t[:, 1], t[:, 2])


# ----- Fourier fields (004_ Eq. 2, 7, 8) ------------------------------------------------------------
def _triple_sum(w: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Σ_ijk w[i, j, k] t[i, 0] t[j, 1] t[k, 2] per point: weights (H, H, H), per-axis tables
    t (H, 3, P); (P,)."""
    h, points = len(w), t.shape[2]
    b = (w.reshape(h, h * h).T @ t[:, 0]).reshape(h, h, points)  # summed over i
    return np.einsum("jp,jp->p", np.einsum("jkp,kp->jp", b, t[:, 2]), t[:, 1])


class FourierField(Field):
    """Φ(x) = Re Σ_f c_f exp(2πi f·x) over integer frequencies f (K, 3), period 1 in cell units.

    Stored as the non-negligible coefficients of a sampled grid; evaluation pairs each f with
    -f (c_-f = conj(c_f) for a real field) and sums a cos θ - b sin θ over half the terms."""

    def __init__(self, freqs, coeffs, n: int, cell=1.0, placement: Similarity | None = None,
                 symmetric: bool = False) -> None:
        super().__init__(cell, placement)
        self.freqs = np.asarray(freqs, dtype=np.int64).reshape(-1, 3)
        self.coeffs = np.asarray(coeffs, dtype=complex).reshape(-1)
        self.n = int(n)
        if len(self.freqs) != len(self.coeffs):
            raise PleError("Fourier field: as many frequencies as coefficients are needed")
        self.symmetric = bool(symmetric)  # coefficients constant on T_d orbits: evaluate by orbits
        self._half = self._half_terms()
        self._orbits = self._orbit_terms() if self.symmetric else None

    # -- fitting (004_ §3.2: samples on the grid x_m = -0.5 + m/N, FFT, then symmetrize) --
    @staticmethod
    def fit(samples, symmetric: bool = True, tol: float = 1e-12, max_terms: int | None = None,
            cell=1.0, placement: Similarity | None = None) -> FourierField:
        """Fit from an (N, N, N) grid of signed-distance (or any real) samples at x_m = -0.5 + m/N.

        ``symmetric`` projects onto the T_d-symmetric basis (004_ Eq. 8), i.e. averages the
        field over the 24 operators; coefficients below ``tol`` times the largest are dropped
        and with ``max_terms`` only about that many (the largest, whole orbits) are kept."""
        g = np.asarray(samples, dtype=float)
        if g.ndim != 3 or len(set(g.shape)) != 1 or g.shape[0] < 2:
            raise PleError(f"Fourier fit needs an (N, N, N) sample grid, got shape {g.shape}")
        if not np.all(np.isfinite(g)):
            raise PleError("Fourier fit: samples contain NaN or inf")
        n = g.shape[0]
        f = np.fft.fftfreq(n, 1.0 / n).round().astype(np.int64)
        # grid starts at -0.5, not 0: c_f = FFT[f] / N³ · exp(iπ (fx + fy + fz)) = FFT[f] / N³ · (-1)^(fx+fy+fz)
        sign = (-1.0) ** (f[:, None, None] + f[None, :, None] + f[None, None, :])
        c = np.fft.fftn(g) / n**3 * sign
        scale = np.abs(c).max()  # tolerance relative to the input: a T_d average may vanish (a gyroid's does)
        if symmetric:
            c = symmetrize_coefficients(c)
        return FourierField._from_grid(c, tol * scale, max_terms, cell, placement, symmetric)

    @staticmethod
    def fit_inside_outside(inside, **options) -> FourierField:
        """Fit from an (N, N, N) Boolean grid: inside samples count -1, outside +1 (004_ §3.2)."""
        m = np.asarray(inside)
        if m.dtype != bool:
            raise PleError("inside/outside samples must be a Boolean grid")
        return FourierField.fit(np.where(m, -1.0, 1.0), **options)

    @staticmethod
    def _from_grid(c, floor, max_terms, cell, placement, symmetric: bool = False) -> FourierField:
        """Keep the coefficients above ``floor`` in magnitude; with ``max_terms``, the largest ones
        down to the max_terms-th magnitude, keeping ties (a T_d orbit or a ±f pair shares one
        magnitude, so symmetry survives the cut)."""
        n = c.shape[0]
        mag = np.abs(c)
        keep = mag > floor
        if max_terms is not None and keep.sum() > max_terms:
            cut = np.sort(mag[keep])[::-1][max_terms - 1]
            keep &= mag >= cut * (1 - 1e-9)
        idx = np.argwhere(keep)
        vals = c[keep]
        freqs = np.where(idx >= (n + 1) // 2, idx - n, idx)
        # special case: a Nyquist frequency -N/2 (even N) stands for both ±N/2; split it evenly
        # so that the field stays real and keeps every sign-flip symmetry between grid points
        for axis in range(3):
            nyq = (n % 2 == 0) & (freqs[:, axis] == -n // 2)
            if nyq.any():
                flipped = freqs[nyq].copy()
                flipped[:, axis] = n // 2
                vals = np.concatenate([np.where(nyq, vals / 2, vals), vals[nyq] / 2])
                freqs = np.concatenate([freqs, flipped])
        return FourierField(freqs, vals, n, cell, placement, symmetric)

    def coefficient_grid(self) -> np.ndarray:
        """The dense (N, N, N) coefficient array in FFT order (split Nyquist terms re-joined)."""
        c = np.zeros((self.n,) * 3, dtype=complex)
        np.add.at(c, tuple((self.freqs % self.n).T), self.coeffs)
        return c

    def symmetrize(self) -> FourierField:
        """Average over the 24 operators of T_d (the projection of 004_ Eq. 8)."""
        c = symmetrize_coefficients(self.coefficient_grid())
        return FourierField._from_grid(c, 1e-15 * np.abs(self.coeffs).max(initial=0.0), None, self.cell,
                                       self.placement, symmetric=True)

    # -- evaluation --
    def _half_terms(self):
        """Frequencies and weights of a cos/sin sum equal to Re Σ c_f e^{2πi f·x}: each ±f pair
        once with weight 2 (the member with the larger key), f = 0 once."""
        m = 2 * self.n + 1
        key = lambda f: ((f[:, 0] + self.n) * m + f[:, 1] + self.n) * m + f[:, 2] + self.n  # noqa: E731
        pos, neg = key(self.freqs), key(-self.freqs)
        has_partner = np.isin(neg, pos)
        # a lone f (its partner fell below the tolerance) keeps weight 1: Re(c e^{iθ}) exactly
        w = np.where((pos == neg) | ~has_partner, 1.0, np.where(pos > neg, 2.0, 0.0))
        sel = w > 0
        return self.freqs[sel].astype(float), self.coeffs[sel], w[sel]

    def _orbit_terms(self):
        """Columns of the T_d orbit sum (004_ Eq. 4): for a representative r of each orbit
        (|r| sorted descending, the product's sign on the last entry, 004_ Eq. 3) and each axis
        permutation σ, the summed exponentials over the 4 even sign patterns are
        4 Π_k cos(2π r_k x_σ(k)) - 4i Π_k sin(2π r_k x_σ(k)); the group sum counts each member of
        an orbit O 24/|O| times, so Re Σ_{h∈O} c_h e^{2πi h·x} = Σ_σ (Re S Π cos + Im S Π sin) / 6
        with S = Σ_{h∈O} c_h. Each column takes one factor per axis, so the columns add up to dense
        weights (H, H, H) of the frequencies on x, y and z: returns H and the cos and sin weights."""
        f = self.freqs
        mags = np.sort(np.abs(f), axis=1)[:, ::-1]
        sign = np.where(np.prod(np.sign(f), axis=1) < 0, -1, 1)
        mags[:, 2] *= sign
        reps, inv = np.unique(mags, axis=0, return_inverse=True)
        total = np.zeros(len(reps), dtype=complex)
        np.add.at(total, inv.reshape(-1), self.coeffs)
        h = int(np.abs(f).max(initial=0)) + 1
        cols_idx, cols_cos, cols_sin = [], [], []
        for perm in itertools.permutations(range(3)):
            cols_idx.append(np.abs(reps) * 3 + np.array(perm)[None, :])  # table row of (|r_k|, axis σ(k))
            cols_cos.append(total.real / 6)
            cols_sin.append(np.sign(reps[:, 2]) * total.imag / 6)  # sin is odd: the sign of r_z
        idx = np.concatenate(cols_idx)
        freq = np.take_along_axis(idx // 3, np.argsort(idx % 3, axis=1), axis=1)  # (columns, 3): on x, y, z
        weights = []
        for w in (np.concatenate(cols_cos), np.concatenate(cols_sin)):
            dense = np.zeros((h, h, h))
            np.add.at(dense, tuple(freq.T), w)
            weights.append(dense)
        return h, weights[0], weights[1]

    def evaluate_local(self, x):
        if self._orbits is not None:
            return self._evaluate_orbits(x)
        f, c, w = self._half
        a, b = (w * c.real), (w * c.imag)
        out = np.empty(len(x))
        for s in range(0, len(x), EVAL_CHUNK):
            theta = (2 * math.pi) * (x[s:s + EVAL_CHUNK] @ f.T)
            out[s:s + EVAL_CHUNK] = np.cos(theta) @ a - np.sin(theta) @ b
        return out

    def _evaluate_orbits(self, x):
        """Symmetric fields: cos/sin of 2π m x_a per axis and frequency m (Chebyshev recurrence,
        no per-term transcendental), then Σ w[i, j, k] t_i(x) t_j(y) t_k(z) over the dense
        weights of ``_orbit_terms``: one matrix product over i, then the sums over k and j."""
        h, wc, ws = self._orbits
        use_sin = np.any(ws != 0)
        out = np.empty(len(x))
        for s in range(0, len(x), EVAL_CHUNK):
            p = x[s:s + EVAL_CHUNK].T  # (3, P)
            c1, s1 = np.cos(2 * math.pi * p), np.sin(2 * math.pi * p)
            ct, st = np.empty((h, 3, p.shape[1])), np.empty((h, 3, p.shape[1]))
            ct[0], st[0] = 1.0, 0.0
            if h > 1:
                ct[1], st[1] = c1, s1
            for m in range(2, h):  # cos(mθ) = 2 cos θ cos((m-1)θ) - cos((m-2)θ), the same for sin
                ct[m] = 2 * c1 * ct[m - 1] - ct[m - 2]
                st[m] = 2 * c1 * st[m - 1] - st[m - 2]
            val = _triple_sum(wc, ct)
            if use_sin:
                val += _triple_sum(ws, st)
            out[s:s + EVAL_CHUNK] = val
        return out

    def arrays(self) -> dict:
        """The coefficient arrays as saved to ``.npz`` (``FourierField.load`` reads them back)."""
        return {"freqs": self.freqs, "coeffs": self.coeffs, "n": np.array(self.n),
                "symmetric": np.array(self.symmetric)}

    @staticmethod
    def load(path, cell=1.0, placement: Similarity | None = None) -> FourierField:
        try:
            with np.load(path, allow_pickle=False) as z:
                sym = bool(z["symmetric"]) if "symmetric" in z.files else False
                return FourierField(z["freqs"], z["coeffs"], int(z["n"]), cell, placement, sym)
        except (OSError, KeyError, ValueError) as exc:
            raise PleError(f"Fourier field file {path}: {exc}") from None


def symmetrize_coefficients(c: np.ndarray) -> np.ndarray:
    """T_d average of a dense FFT-ordered coefficient grid: (1/24) Σ_Q c[Q h] (004_ Eq. 1, 8).

    If Φ(x) = Σ c_f e^{2πi f·x} then Φ(Qx) has coefficient c_{Qh} at h (Q orthogonal), so the
    average over the group is the average of the 24 re-indexed grids."""
    n = c.shape[0]
    f = np.fft.fftfreq(n, 1.0 / n).round().astype(np.int64)
    h = np.stack(np.meshgrid(f, f, f, indexing="ij"), axis=-1).reshape(-1, 3)
    out = np.zeros(n**3, dtype=complex)
    for q in TD_OPERATORS.astype(np.int64):
        qh = (h @ q.T) % n
        out += c[qh[:, 0], qh[:, 1], qh[:, 2]]
    return (out / len(TD_OPERATORS)).reshape(c.shape)


def sample_grid(fn, n: int) -> np.ndarray:
    """Samples of ``fn(points (M, 3)) -> (M,)`` on the N³ grid x_m = -0.5 + m/N (004_ §3.2)."""
    t = -0.5 + np.arange(n) / n
    pts = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.asarray(fn(pts), dtype=float).reshape(n, n, n)


# ----- the filter ---------------------------------------------------------------------------------------
class ImplicitFilter(Filter):
    """A node survives where ``field(centre) < level`` (network) or ``|field| < level`` (sheet)."""

    def __init__(self, field: Field, level: float = 0.0, variant: str = "network") -> None:
        if not isinstance(field, Field):
            raise PleError(f"implicit filter needs a Field, got {type(field).__name__}")
        if variant not in VARIANTS:
            raise PleError(f"implicit filter variant {echo(variant)}: expected network or sheet")
        level = float(level)
        if not math.isfinite(level):
            raise PleError(f"implicit filter level must be finite, got {level}")
        if variant == "sheet" and level <= 0:
            raise PleError(f"a sheet needs a positive level (half-thickness in field units), got {level}")
        self.field, self.level, self.variant = field, level, variant

    def node_mask(self, lat, node_index, center, radius):
        v = self.field(center)
        return (np.abs(v) < self.level) if self.variant == "sheet" else (v < self.level)
