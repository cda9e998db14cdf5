"""Constant-radius BeCOTS lattices and their connectors (thesis §4.5.3): connector classes by
node-pattern and incident beam ends, congruent within a class (Kabsch alignment), connector
meshes by manifold3d Booleans."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..algebra.vectors import unit
from ..errors import PleError, echo
from ..model.becots import TWO_PI, becots_of
from ..model.lattice import Lattice


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
    x = unit(other - (other @ e0) * e0)
    return np.stack([x, np.cross(e0, x), e0], axis=1)


def _ring_basis(d: np.ndarray, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ux = frame[:, 0] - (frame[:, 0] @ d) * d
    ux = unit(ux) if np.linalg.norm(ux) > 1e-6 else unit(np.cross(d, frame[:, 1]))
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
    from manifold3d import Manifold  # optional: only connector meshes need manifold3d

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
        raise PleError(f"constant radius {echo(radius)} / beam radius {echo(beam_radius)}: "
                       "need 0 < beam radius <= radius")
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
            dirs = np.array([unit(centers[other] - centers[row]) for _, _, other in inc]).reshape(-1, 3)
            gen.append(connector_points(centers[row], dirs, radius, beam_radius, grow))
        template = gen[0]
        motions = np.array([kabsch(template, g) for g in gen])
        row = rows[0]
        dirs = np.array([unit(centers[other] - centers[row]) for _, _, other in sorted(ends[row])]).reshape(-1, 3)
        mesh = connector_mesh(centers[row], dirs, radius, beam_radius, grow)
        out.append(ConnectorClass(key, template, mesh, motions, ev.node_index[rows]))
    beams = {"start": centers[ev.beam_nodes[:, 0]], "end": centers[ev.beam_nodes[:, 1]], "radius": beam_radius}
    return out, beams
