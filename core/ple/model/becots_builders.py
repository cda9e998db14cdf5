"""BeCOTS lattices (thesis §4.5, §6.3): named connectivities over a field, the filtered
multi-level variant, stacks of layers and the continuous layer coordinate of a stack."""

from __future__ import annotations

import numpy as np

from ..algebra.vectors import rotate, unit
from ..errors import PleError, echo
from .becots import BeCOTSField, Stack, becots_counts, becots_of
from .lattice import Lattice


def set_field(lat: Lattice, fld: BeCOTSField, counts=(1, 1), closed: bool = False, stack: Stack | None = None) -> None:
    """Program API: ``set_field(lat, fld, counts)`` is ``lat.set_field(fld, counts)``."""
    lat.set_field(fld, counts, closed, stack)


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
        raise PleError(f"connectivity {echo(connectivity)}: expected one of {', '.join(CONNECTIVITIES)}")
    nu, nv = becots_counts(counts)
    p = int(period)
    if p < 1 or nu % p or nv % p:
        raise PleError(f"period {echo(period)}: must be >= 1 and divide the counts ({nu}, {nv})")
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
    lat.set_field(fld, (nu // p, nv // p), closed)
    return lat


def stack_lattice(fld: BeCOTSField, counts, layers: int, spacing: float, mode: str = "raise",
                  connectivity: str = "triangle", radius: float = 0.05, links=((0, 0, 0, 0),)) -> Lattice:
    """BeCOTS stack (§6.3): ``layers`` layers sharing field S, layer k with corner
    A_k = A + k·spacing·e, e = T (constant-distance raise) or the cone normal at A (normal
    offset); ``links`` (n1, n2, di, dj) join node n1 of layer k to node n2 of layer k+1.

    Stored as one BeCOTS slab whose template node-group holds every layer (node id
    ``layer * nodes_per_layer + n``), so every command works unchanged."""
    if mode not in ("raise", "normal"):
        raise PleError(f"stack mode {echo(mode)}: expected raise or normal")
    if fld.kind == "translation":
        direction = unit(np.cross(fld.tu, fld.tv))
    elif mode == "raise":
        direction = fld.axis
    else:  # normal of the cone at A: the part of T perpendicular to the generator FA
        fa = unit(fld.a - fld.apex)
        direction = unit(fld.axis - (fld.axis @ fa) * fa)
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
    lat.set_field(fld, becots_counts(counts), False, Stack(layers, nn, step, mode))
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
    back = fld.apex + rotate(q - fld.apex, fld.axis, -theta)  # into the half-plane of A (and of L)
    if fld.kind == "cylinder":  # no apex: the nearest point of L in that half-plane
        return (back - a) @ step / (step @ step)
    # central projection from F onto L: F + s (back - F) = A + t step, solved by crossing with d
    d = back - fld.apex
    fa = a - fld.apex
    sd = np.cross(step, d)
    den = np.einsum("ij,ij->i", sd, sd)
    t = -np.einsum("ij,ij->i", np.cross(fa, d), sd) / np.where(den > 0, den, 1.0)
    return np.where(den > 0, t, 0.0)
