"""Moved frames, template nodes and corners read as GUI edits (thesis §6.2.2): ``SetPlacement``,
``SetDirection``, ``SetBecots``, ``MoveNode`` of ``ple.program.snippets``.

A part counts as moved by the user when its matrix differs from the one the add-on last wrote
(``RigState.expected``) by more than ``MOVE_TOL``; the numbers read keep the precision the
float32 frame carries (``ple.algebra.precision``)."""

from __future__ import annotations

import numpy as np

from ..corelink import PleError, cage, precision, snippets
from ..session import RigState
from .model import becots_corners, flat, parts, state_of

FRAME_NAMES = ("G", "u", "v", "w")
MOVE_TOL = 1e-6  # a frame or node counts as moved by the user beyond this (float32 matrices)


def baseline(rig) -> None:
    """Take the parts' current matrices as what was drawn (after loading a file, undo or enabling
    the add-on), so that moves made before the program can run are still read as user moves later."""
    st = state_of(rig)
    for key, obj in parts(rig).items():
        if key in FRAME_NAMES or (isinstance(key, tuple) and key[0] in ("node", "corner")):
            st.expected[key] = flat(obj.matrix_basis)
    st.cumulative = tuple(rig.ple.cumulative)


def moved(obj, expected: dict, key) -> bool:
    old = expected.get(key)
    return old is not None and max(abs(a - b) for a, b in zip(flat(obj.matrix_basis), old)) > MOVE_TOL


def user_edits(rig, st: RigState) -> list:
    """Edits for frames and template nodes the user moved since the last drawing (§6.2.2)."""
    lat = st.lattice
    if lat is None:
        return []
    p = parts(rig)
    out = []
    for key in FRAME_NAMES:
        obj = p.get(key)
        if obj is None or not moved(obj, st.expected, key):
            continue
        m = np.array(obj.matrix_basis)
        scale = max(1.0, float(np.abs(m[:3, 3]).max()))  # numbers keep the precision the frame carries
        if key == "G":
            sim = precision.frame_similarity(cage.placement_from_frame(m, lat.placement), scale)
            out.append(snippets.SetPlacement(sim))
            continue
        axis_n = "uvw".index(key)
        cum = cage.shows_cumulative(lat, key, rig.ple.cumulative[axis_n])
        sim = precision.frame_similarity(cage.direction_from_frame(lat, key, m, cum), scale)
        out.append(snippets.SetDirection(key, None, sim, cum))
    corners = becots_corners(lat)
    if corners and any(p.get(("corner", c)) is not None and moved(p[("corner", c)], st.expected, ("corner", c))
                       for c in "ABCD"):
        at = [tuple(p[("corner", c)].matrix_basis.translation) for c in "ABCD"]
        scale = max(1.0, float(np.abs(at).max()))
        out.append(snippets.SetBecots(tuple(precision.frame_point(c, scale) for c in at), tuple(lat.becots.counts)))
    for n in range(len(lat.nodes)):
        obj = p.get(("node", n))
        if obj is None or not moved(obj, st.expected, ("node", n)):
            continue
        loc, _rot, scale = obj.matrix_basis.decompose()
        s = np.array(scale)
        if np.abs(s - s.mean()).max() > 1e-4 * abs(s.mean()) or s.mean() <= 0:
            raise PleError(f"template node {n}: scale it uniformly (the scale is the ball's radius)")
        node = lat.nodes[n]
        loc = precision.frame_point(loc, max(1.0, float(np.abs(np.array(loc)).max())))
        center = tuple(loc) if np.abs(np.array(loc) - node.center).max() > MOVE_TOL else None
        moved_radius = abs(s.mean() - node.radius) > MOVE_TOL * max(1.0, node.radius)
        radius = precision.frame_number(s.mean()) if moved_radius else None
        if center is not None or radius is not None:
            out.append(snippets.MoveNode(n, center, radius))
    return out


def register() -> None:
    pass


def unregister() -> None:
    pass
