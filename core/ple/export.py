"""Mesh and lattice export: binary STL (own numpy writer, streaming), binary PLY and OBJ (own
writers), GLB (trimesh), 3MF (own strict writer, ``ple.threemf``) and 3MF with the Beam Lattice
extension (balls and beams beside the triangle mesh).

Every mesh is snapped to a float32 grid and welded before writing (``ple.weld``), so the file
reads back watertight; units are explicit (``unit``, default mm); glTF and OBJ are Y-up.

Every write is atomic (``ple.files.atomic_path``): on any error no partial file is left.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import trimesh

from .errors import PleError
from .files import atomic_path
from .threemf import NS_BALLS, NS_BEAM, NS_CORE  # noqa: F401 - re-exported

MESH_FORMATS = ("stl", "ply", "obj", "glb", "3mf")
STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
STL_MAX_TRIANGLES = 2**32 - 1


def mesh_format(path) -> str:
    """The output format named by ``path``'s suffix (one of MESH_FORMATS)."""
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in MESH_FORMATS:
        raise PleError(f"{path}: unknown mesh format {suffix!r} (expected .{', .'.join(MESH_FORMATS)})")
    return suffix


def stl_records(triangles: np.ndarray, faces: np.ndarray | None = None) -> np.ndarray:
    """Binary STL records for triangles (k, 3, 3), or for ``vertices[faces]`` when ``faces``
    (k, 3) is given: unit normals (zero for degenerate faces), computed in float32."""
    if faces is None:
        tri = np.asarray(triangles, np.float32).reshape(-1, 3, 3)
    else:
        tri = np.asarray(triangles, np.float32)[faces]
    rec = np.empty(len(tri), STL_RECORD)
    rec["vertices"] = tri
    rec["attr"] = 0
    a = tri[:, 1] - tri[:, 0]
    b = tri[:, 2] - tri[:, 0]
    n = np.empty_like(a)
    n[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    n[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    n[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    ln = np.sqrt(np.einsum("ij,ij->i", n, n))
    ln[ln == 0] = 1
    n /= ln[:, None]
    rec["normal"] = n
    return rec


class StlWriter:
    """Incremental binary STL: header, then chunks of triangles, then the count is patched.

    Use as a context manager around ``ple.files.atomic_path`` output: memory stays bounded
    by the largest chunk, whatever the total."""

    def __init__(self, fh, header: bytes = b"PLE binary STL"):
        self.fh = fh
        self.count = 0
        fh.write(header[:80].ljust(80, b" "))
        fh.write(struct.pack("<I", 0))

    def write(self, triangles: np.ndarray, faces: np.ndarray | None = None) -> None:
        """Append triangles (k, 3, 3), or ``vertices[faces]`` for vertices (V, 3), faces (k, 3)."""
        rec = stl_records(triangles, faces)
        self.count += len(rec)
        if self.count > STL_MAX_TRIANGLES:
            raise PleError(f"binary STL holds at most {STL_MAX_TRIANGLES} triangles; use a smaller --region")
        self.fh.write(memoryview(rec).cast("B"))

    def close(self) -> None:
        self.fh.seek(80)
        self.fh.write(struct.pack("<I", self.count))
        self.fh.seek(0, 2)


def write_stl(path, chunks: Iterable, header: bytes = b"PLE binary STL", grid: float | None = None) -> int:
    """Write chunks to binary STL atomically; a chunk is triangles (k, 3, 3) or a pair
    (vertices (V, 3), faces (k, 3)). With ``grid`` every vertex is snapped to that float32 grid
    (``ple.weld``; the same grid for every chunk) and triangles whose corners then coincide are
    dropped. Returns the number of triangles."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        w = StlWriter(fh, header)
        for chunk in chunks:
            tri = chunk[0][chunk[1]] if isinstance(chunk, tuple) else np.asarray(chunk, float).reshape(-1, 3, 3)
            if grid is not None:
                from .weld import snap

                tri = snap(tri, grid)
                ne = [np.any(tri[:, a] != tri[:, b], axis=1) for a, b in ((0, 1), (1, 2), (2, 0))]
                tri = tri[ne[0] & ne[1] & ne[2]]
            w.write(tri)
        w.close()
    return w.count


UNITS = {"um": ("micron", 1e-6), "mm": ("millimeter", 1e-3), "cm": ("centimeter", 1e-2),
         "in": ("inch", 0.0254), "ft": ("foot", 0.3048), "m": ("meter", 1.0)}
DEFAULT_UNIT = "mm"
Y_UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # (x, y, z) -> (x, z, -y): Z-up data in a Y-up file


def unit_name(unit: str) -> str:
    """The 3MF name of a unit ("mm" -> "millimeter")."""
    if unit not in UNITS:
        raise PleError(f"--unit {unit!r}: expected one of {', '.join(UNITS)}")
    return UNITS[unit][0]


def prepare(vertices, faces, fmt: str, unit: str = DEFAULT_UNIT, grid: float | None = None):
    """Vertices and faces as they go into a file of format ``fmt``: turned Y-up for glTF and
    OBJ, scaled to metres for glTF (its unit by specification), snapped to the float32 grid
    and welded (``ple.weld``) so the file reads back with the topology it was checked with.
    ``grid``: the snap grid (default: from these vertices' bounds; ignored for glTF, whose
    coordinates are rescaled). Returns (vertices exactly in float32, faces, weld stats)."""
    from .weld import grid_spacing, weld

    unit_name(unit)
    v = np.asarray(vertices, float).reshape(-1, 3)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    if fmt in ("glb", "obj"):
        v = v @ Y_UP.T
    if fmt == "glb":
        v = v * UNITS[unit][1]
        grid = None
    if grid is None:
        grid = grid_spacing(v.min(axis=0), v.max(axis=0)) if len(v) else 1.0
    return weld(v, f, grid)


def export_mesh(mesh: trimesh.Trimesh, path, unit: str = DEFAULT_UNIT, grid: float | None = None) -> dict:
    """Write a mesh; the format follows the suffix. Coordinates are in ``unit`` (default mm:
    written into 3MF, stated in the STL header, PLY and OBJ comments; glTF is converted to
    metres, its unit). glTF and OBJ are Y-up (converted from our Z-up). Coordinates are
    snapped to float32 and welded first (``prepare``); returns the weld statistics."""
    fmt = mesh_format(path)
    v, f, stats = prepare(mesh.vertices, mesh.faces, fmt, unit, grid)
    if fmt == "stl":
        write_stl(path, [(v, f)], header=stl_header(unit))
    elif fmt == "3mf":
        from .threemf import write_3mf

        write_3mf(path, v, f, unit_name(unit))
    elif fmt == "ply":
        write_ply(path, v, f, unit)
    elif fmt == "obj":
        write_obj(path, v, f, unit)
    else:
        out = trimesh.Trimesh(v.astype(np.float32), f, process=False)
        with atomic_path(path) as tmp:
            tmp.write_bytes(trimesh.exchange.gltf.export_glb(out, include_normals=False))
    return stats


def stl_header(unit: str) -> bytes:
    return f"PLE binary STL, unit {unit}, Z up".encode()


def write_ply(path, vertices, faces, unit: str = DEFAULT_UNIT) -> None:
    """Binary little-endian PLY: float32 vertices, uchar-counted int32 faces; unit in a comment."""
    v = np.ascontiguousarray(vertices, "<f4")
    rec = np.empty(len(faces), np.dtype([("n", "u1"), ("f", "<i4", (3,))]))
    rec["n"] = 3
    rec["f"] = faces
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"comment PLE lattice mesh, unit {unit}, Z up\n"
              f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(rec)}\nproperty list uchar int vertex_indices\nend_header\n")
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.encode())
        fh.write(v.tobytes())
        fh.write(rec.tobytes())


def write_obj(path, vertices, faces, unit: str = DEFAULT_UNIT) -> None:
    """Wavefront OBJ (Y up, 9 significant digits: float32 values exactly); unit in a comment."""
    import io

    buf = io.StringIO()
    buf.write(f"# PLE lattice mesh, unit {unit}, Y up\n")
    if len(vertices):
        np.savetxt(buf, np.asarray(vertices, np.float32).astype(float), fmt="v %.9g %.9g %.9g")
    if len(faces):
        np.savetxt(buf, np.asarray(faces, np.int64) + 1, fmt="f %d %d %d")
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue())


def write_beam_lattice_3mf(path, center, radius, beam_nodes, mesh=None, unit: str = DEFAULT_UNIT) -> None:
    """A 3MF package with the Beam Lattice extension (balls and cone beams). With ``mesh``
    (the lattice's watertight triangle mesh) the same object carries its triangles and the
    extensions are not required, so consumers without beam support print the triangles;
    without it the file holds beams only and requires the extensions."""
    from .threemf import write_3mf

    if mesh_format(path) != "3mf":
        raise PleError(f"{path}: a beam lattice is written as .3mf")
    if mesh is None:
        v, f = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    else:
        v, f, _ = prepare(mesh.vertices, mesh.faces, "3mf", unit)
    write_3mf(path, v, f, unit_name(unit), (center, radius, beam_nodes))
