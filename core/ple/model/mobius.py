"""Möbius steady patterns, slabs, maps and lattices; Trans-Möbius Interpolant maps (thesis §11.2–11.4).

Node-group (i, j, k) of a Möbius lattice is ``W**k ∘ V**j ∘ U**i ∘ G`` applied to the template
node-group, for planar Möbius transformations U, V, W and a Möbius frame G (§11.3). Möbius
transformations act in 3D by their Poincaré extension, which maps balls to balls: every node
is rectified exactly, with no sphere fitting (§11.3: "all rectified nodes are clines").
Beams stay straight cone-beams between the mapped balls, so they are not steady (§11.3).

A TMI map (§11.4) is a Möbius steady 2-map whose U and V commute: a circle inversion of a
COTS map. ``TMIMap.from_six`` follows §11.4.1, ``TMIMap.from_five`` §11.4.2.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import replace

import numpy as np

from ..algebra.mobius import Cline, Mobius, as_complex, map_balls
from ..algebra.precision import FLOAT32_TOL
from ..algebra.similarity import Similarity
from ..errors import PleError, echo
from .groupmap import GroupMap
from .lattice import Lattice


def _power_table(g: Mobius, idx: np.ndarray) -> np.ndarray:
    """``g**i`` matrices for an integer index array, computed once per distinct index."""
    if idx.size == 0:
        return np.zeros((0, 2, 2), complex)
    uniq, inv = np.unique(idx, return_inverse=True)
    return g.power_matrices(uniq.astype(float))[inv.reshape(-1)]


class MobiusGroups(GroupMap):
    """Group (i, j, k) placed by ``W**k ∘ V**j ∘ U**i ∘ G`` (Möbius steady 3-pattern, §11.3)."""

    kind = "Möbius"

    def __init__(self, u: Mobius, v: Mobius | None = None, w: Mobius | None = None,
                 frame: Mobius | None = None):
        for name, g in (("U", u), ("V", v), ("W", w), ("frame", frame)):
            if g is not None and not isinstance(g, Mobius):
                raise PleError(f"Möbius lattice: {name} must be a Mobius, got {type(g).__name__}")
        ident = Mobius.identity()
        self.u, self.v, self.w = u, v or ident, w or ident
        self.frame = frame or ident

    def matrices(self, i, j, k) -> np.ndarray:
        """Normalized matrices (N, 2, 2) of the groups' transformations."""
        i, j, k = (np.asarray(x, dtype=np.int64).reshape(-1) for x in (i, j, k))
        m = _power_table(self.w, k) @ _power_table(self.v, j) @ _power_table(self.u, i)
        return m @ self.frame.m[None]

    def map_balls(self, i, j, k, centers, radii):
        m = self.matrices(i, j, k)
        return map_balls(m, np.asarray(centers, float).reshape(-1, 3), np.asarray(radii, float).reshape(-1))

    def map_points(self, i, j, k, points: np.ndarray) -> np.ndarray:
        """Images of complex points ``points`` (N,) in groups (i, j, k) (real i, j, k allowed)."""
        i, j, k = (np.asarray(x, dtype=float).reshape(-1) for x in (i, j, k))
        m = (self.w.power_matrices(k) @ self.v.power_matrices(j) @ self.u.power_matrices(i)) @ self.frame.m[None]
        z = np.asarray(points, dtype=complex).reshape(-1)
        return (m[:, 0, 0] * z + m[:, 0, 1]) / (m[:, 1, 0] * z + m[:, 1, 1])

    def describe(self) -> dict:
        def coeffs(g: Mobius) -> list:
            return [[x.real, x.imag] for x in g.coefficients]

        return {"kind": self.kind, "U": coeffs(self.u), "V": coeffs(self.v), "W": coeffs(self.w),
                "frame": coeffs(self.frame),
                "note": "nodes are exact images of the template balls (Poincaré extension); beams are "
                        "straight cone-beams, not steady: queries test every element, meshes and "
                        "area/volume take the per-hub path"}


def mobius_lattice(template: Lattice, u: Mobius, v: Mobius | None = None, w: Mobius | None = None,
                   counts=(1, 1, 1), frame: Mobius | None = None) -> Lattice:
    """A Möbius steady lattice: the template's nodes and beam-patterns, groups placed by
    ``W**k ∘ V**j ∘ U**i ∘ frame`` for ``counts`` = (nu, nv, nw) groups (§11.3)."""
    lat = template.copy()
    lat.set_group_map(MobiusGroups(u, v, w, frame), counts)
    return lat


def mobius_frames_lattice(template: Lattice, x, y, z, counts=(1, 1)) -> Lattice:
    """The Möbius steady 2-pattern of three Möbius frames (§11.3): frame X places the template
    (given in the identity frame), U takes X to Y and V takes X to Z."""
    fx, fy, fz = ([as_complex(p) for p in f] for f in (x, y, z))
    u, v = Mobius.between_frames(fx, fy), Mobius.between_frames(fx, fz)
    nu, nv = _pair(counts)
    return mobius_lattice(template, u, v, None, (nu, nv, 1), Mobius.from_frame(*fx))


def _pair(counts) -> tuple[int, int]:
    try:
        nu, nv = (int(c) for c in counts)
    except (TypeError, ValueError):
        raise PleError(f"counts {echo(counts)}: expected two integers") from None
    return nu, nv


class TMIMap:
    """A Trans-Möbius Interpolant M(u, v) = U**u ∘ V**v (origin), U and V commuting (§11.4)."""

    def __init__(self, u: Mobius, v: Mobius, origin: complex):
        self.u, self.v, self.origin = u, v, complex(origin)

    @staticmethod
    def from_six(a, b, c, x, y, z) -> TMIMap:
        """§11.4.1: Möbius frames H1 = {A, B, C}, H2 = {X, Y, Z}; M(0,0)=B, M(0,1)=C, M(1,0)=Y,
        M(1,1)=Z (A and X only choose the inversion)."""
        pa, pb, pc, px, py, pz = (as_complex(p) for p in (a, b, c, x, y, z))
        g = Mobius.between_frames((pa, pb, pc), (px, py, pz))
        if g.is_similarity:  # H1 and H2 similar: the TMI is the COTS of B, C, Y, Z
            return TMIMap(Mobius.from_similarity(Similarity.from_point_pairs(_xy(pb), _xy(pc), _xy(py), _xy(pz))),
                          Mobius.from_similarity(Similarity.from_point_pairs(_xy(pb), _xy(py), _xy(pc), _xy(pz))), pb)
        f = g.fixed_points()[0]
        scale = max(abs(q - f) for q in (pb, pc, py, pz))
        inv = Cline.circle(f, scale)  # R: any circle centred on a fixed point of G
        rb, rc, ry, rz = (complex(inv.invert(np.array([q]))[0]) for q in (pb, pc, py, pz))
        u1 = Similarity.from_point_pairs(_xy(rb), _xy(rc), _xy(ry), _xy(rz))  # U' takes {B', C'} to {Y', Z'}
        v1 = Similarity.from_point_pairs(_xy(rb), _xy(ry), _xy(rc), _xy(rz))  # V' takes {B', Y'} to {C', Z'}
        return TMIMap(Mobius.conjugated(u1, inv), Mobius.conjugated(v1, inv), pb)

    @staticmethod
    def from_five(a, b, c, d, e) -> TMIMap:
        """§11.4.2: M(0,0)=A, M(1,0)=B, M(0,1)=C, M(1,1)=D, M(.5,0)=E."""
        pa, pb, pc, pd, pe = (as_complex(p) for p in (a, b, c, d, e))
        swap = Mobius.between_frames((pa, pb, pc), (pd, pc, pb))  # I: {A,B,C} -> {D,C,B}
        pz = complex(swap(np.array([pe]))[0])  # Z = I(E) = M(.5, 1)
        six = TMIMap.from_six(pe, pa, pb, pz, pc, pd)  # its u runs A->C: swap the parameters
        u, v = six.v, six.u
        # §11.4.2: the rotation angle of the COTS similarity may sit on the wrong side of ±π
        # ("jumps" that break M(.5,0) = E); the corners hold for every branch, so keep the
        # branch of U's angle that interpolates E
        sim, mr = u.similarity_part()
        if abs(abs(sim.r[2]) - 1) < 1e-12:  # a rotation about z: its angle has branches
            # ±1 turn flips U**.5 by a half turn; ±2 turns would meet E again but wrap the map
            cands = [Mobius(u.m, (replace(sim, angle=sim.angle + 2 * math.pi * k), mr)) for k in (0, -1, 1)]
            errs = [abs(TMIMap(c, v, six.origin)(0.5, 0.0) - pe) for c in cands]
            tol = 1e-9 * max(1.0, max(abs(p) for p in (pa, pb, pc, pd)))
            u = next((c for c, e in zip(cands, errs) if e <= tol), cands[int(np.argmin(errs))])
        return TMIMap(u, v, six.origin)

    def __call__(self, u, v) -> np.ndarray:
        """Complex points M(u, v) for arrays u, v (broadcast)."""
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        m = self.u.power_matrices(u.reshape(-1)) @ self.v.power_matrices(v.reshape(-1))
        z = self.origin
        return ((m[:, 0, 0] * z + m[:, 0, 1]) / (m[:, 1, 0] * z + m[:, 1, 1])).reshape(u.shape)

    def lattice(self, template: Lattice, counts=(4, 4)) -> Lattice:
        """A TMI slab lattice: node-group (i, j) = U**(i/nu) ∘ V**(j/nv) ∘ template, for
        (nu + 1) x (nv + 1) groups so that the corner groups sit at the control corners."""
        nu, nv = _pair(counts)
        if nu < 1 or nv < 1:
            raise PleError(f"TMI counts {echo(counts)}: need at least one cell per direction")
        return mobius_lattice(template, self.u ** (1.0 / nu), self.v ** (1.0 / nv), None, (nu + 1, nv + 1, 1))


def _xy(z: complex) -> tuple[float, float]:
    return (z.real, z.imag)


# ----- control frames: how a Möbius lattice is edited by frames (the add-on's handles) -------------
CONTROL_NAMES = ("X", "Y", "Z", "W")  # X places the template; U takes X to Y, V takes X to Z, W takes X to W


def control_frames(lat: Lattice) -> dict:
    """The Möbius frames {A, B, C} (complex triples) that control a Möbius lattice (§11.3):
    X = frame G, Y = U∘G, Z = V∘G, W = W∘G, each the images of 0, 1, i; only the directions
    whose transformation is not the identity (or X alone)."""
    gm = lat.group_map
    if not isinstance(gm, MobiusGroups):
        raise PleError("control frames: the lattice is not a Möbius lattice (mobius_lattice, "
                       "mobius_frames_lattice or a TMI map)")
    ident = Mobius.identity()
    out = {"X": gm.frame.frame()}
    for name, g in (("Y", gm.u), ("Z", gm.v), ("W", gm.w)):
        if not g.allclose(ident):
            out[name] = (g @ gm.frame).frame()
    for name, f in out.items():
        if not all(np.isfinite(complex(p)) for p in f):
            raise PleError(f"control frame {name} sends a point to infinity: it cannot be shown as a frame")
    return out


def with_control_frames(lat: Lattice, frames: dict) -> Lattice:
    """The Möbius lattice with its controls moved: frames {name: (A, B, C)} replace those of
    ``control_frames`` (missing names keep theirs); U = between_frames(X, Y), V from Z, W from W."""
    have = control_frames(lat)
    bad = sorted(set(frames) - set(have))
    if bad:
        raise PleError(f"control frame {echo(bad[0])}: this lattice has only {', '.join(have)}")
    moved = {k: tuple(as_complex(p) for p in v) for k, v in frames.items()}
    moved = {k: v for k, v in moved.items() if not unmoved(v, have[k])}
    if not moved:  # every frame is the lattice's own, read back through float32: the lattice itself
        return lat.copy()
    f = {**have, **moved}
    gx = Mobius.from_frame(*f["X"])
    u, v, w = (Mobius.between_frames(f["X"], f[n]) if n in f else None for n in ("Y", "Z", "W"))
    out = lat.copy()
    out.set_group_map(MobiusGroups(u or Mobius.identity(), v, w, gx), lat.counts)
    return out


def unmoved(frame, own, ulps: float = 8.0) -> bool:
    """True when ``frame`` {A, B, C} is ``own`` read back through float32 (a control frame shown by
    Blender's float32 matrices and not dragged): every point within ``ulps`` float32 units in the
    last place of the frame's size. Such a frame keeps the program's exact Möbius map, so an
    undragged rig meshes as the program does."""
    size = max(1.0, *(abs(as_complex(p)) for p in own))
    return all(abs(as_complex(p) - as_complex(q)) <= ulps * FLOAT32_TOL * size for p, q in zip(frame, own))


def frame_handles(frame) -> tuple[np.ndarray, np.ndarray]:
    """A Möbius frame {A, B, C} shown as a similarity frame and a handle: the 4x4 matrix with
    origin A, x axis along AB scaled |AB| (z up, the plane z = 0) and C in that frame's
    coordinates (3,). A similarity frame has C at (0, 1, 0); moving C bends the frame."""
    a, b, c = (as_complex(p) for p in frame)
    ab = b - a
    if abs(ab) == 0:
        raise PleError("Möbius frame: A and B coincide")
    s, t = abs(ab), cmath.phase(ab)
    m = np.eye(4)
    m[:2, :2] = s * np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    m[2, 2] = s
    m[:2, 3] = (a.real, a.imag)
    local = (c - a) / ab  # the inverse similarity applied to C
    return m, np.array([local.real, local.imag, 0.0])


def frame_from_handles(matrix, handle) -> tuple[complex, complex, complex]:
    """The Möbius frame {A, B, C} of a frame matrix (4x4) and its C handle (frame coordinates):
    A = the origin, B = the tip of the x axis, C = the handle, projected on the plane z = 0."""
    m = np.asarray(matrix, float).reshape(4, 4)
    pts = m[:3, :3] @ np.array([[0, 0, 0], [1, 0, 0], list(np.asarray(handle, float).reshape(3))]).T + m[:3, 3:]
    if not np.all(np.isfinite(pts)):
        raise PleError("Möbius frame: the frame or its handle is not finite")
    return tuple(complex(x, y) for x, y in pts[:2].T)


def control_frames_code(frames: dict, digits: int = 6) -> str:
    """A program line that applies moved control frames (the add-on's snippet of frame drags):
    ``lat = with_control_frames(lat, {"Y": ((x, y), (x, y), (x, y)), …})``."""
    def pt(z: complex) -> str:
        return f"({round(z.real, digits)!r}, {round(z.imag, digits)!r})"

    body = ", ".join(f'"{k}": ({", ".join(pt(as_complex(p)) for p in frames[k])})' for k in sorted(frames))
    return f"lat = with_control_frames(lat, {{{body}}})"
