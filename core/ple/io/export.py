"""Mesh and lattice files: binary STL (own numpy writer, streaming), binary PLY and OBJ (own
writers), GLB (trimesh), 3MF (own strict writer, ``ple.io.threemf``), 3MF with the Beam Lattice
extension (balls and beams beside the triangle mesh), meshes of lattice regions written straight
to a file, and BeCOTS connector sets.

Every mesh is snapped to a float32 grid and welded before writing (``ple.meshing.weld``), so the
file reads back watertight; units are explicit (``unit``, default mm) and the axes follow each
format's convention (``ple.io.formats``: glTF and OBJ are Y-up, glTF in metres).

Every write is atomic (``ple.io.files.atomic_path``): on any error no partial file is left.
"""

from __future__ import annotations

import io
import json
import os
import stat
import struct
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import PleError
from ..meshing.tessellate import ArrayPool, ordered_map  # buffers and ordered threads, no meshing
from ..meshing.weld import (
    COLLAPSE_GRIDS,
    collapse_short_edges,
    edge_manifold,
    grid_spacing,
    snap_triangles,
    snapped_slices,
    unique_rows,
    weld,
)
from .files import (
    DirectWriter,
    WriteBehind,
    atomic_path,
    check_finite_array,
)
from .formats import DEFAULT_UNIT, MESH_FORMATS, format_named, from_file_axes, mesh_format, to_file_axes, unit_name
from .threemf import NS_BALLS, NS_BEAM, NS_CORE, package_bytes, write_3mf  # noqa: F401 - NS_* re-exported

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh

try:  # the compiled encoder (setup.py, optional): the numpy one's bytes, about 10x faster
    from . import _stlcodec as _codec
except ImportError:  # not built (no C compiler): numpy encodes
    _codec = None
if sys.byteorder != "little":  # it writes records in the machine's order
    _codec = None

STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
STL_MAX_TRIANGLES = 2**32 - 1
ENCODE_SLICE = 1 << 15  # faces encoded at a time: the float32 triangles and normals of a slice stay in cache


def stl_records(triangles: np.ndarray, faces: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """Binary STL records for triangles (k, 3, 3), or for ``vertices[faces]`` when ``faces``
    (k, 3) is given: unit normals (zero for degenerate faces), computed in float32. ``out``: k
    records to fill (a slice of a larger block) instead of new ones. Encoded ``ENCODE_SLICE``
    faces at a time (the same values: every record is computed on its own)."""
    if faces is not None and _codec is not None:  # compiled, no snap: the same records
        return _compiled(triangles, faces, None, lambda k: np.empty(k, STL_RECORD) if out is None else out)
    src = np.asarray(triangles, np.float32)
    src = src.reshape(-1, 3, 3) if faces is None else src.reshape(-1, 3)
    k = len(src) if faces is None else len(faces)
    rec = np.empty(k, STL_RECORD) if out is None else out
    for lo in range(0, k, ENCODE_SLICE):
        tri = src[lo:lo + ENCODE_SLICE] if faces is None else src[faces[lo:lo + ENCODE_SLICE]]
        _encode(tri, rec[lo:lo + ENCODE_SLICE])
    return rec


def _compiled(vertices, faces, grid: float | None, records, scratch: bool = False) -> np.ndarray:
    """The records of ``vertices[faces]`` by the compiled encoder (snapped to ``grid`` when
    given, faces with coinciding corners then dropped), written into ``records(k)``; with
    ``scratch``, into ``records(k + m)``, whose m records after the k faces' hold the encoder's
    float32 vertices (pooled buffers: reused with them, no fresh pages for every box)."""
    v = np.ascontiguousarray(vertices, np.float64).reshape(-1, 3)
    f = np.asarray(faces).reshape(-1, 3)
    f = np.ascontiguousarray(f, f.dtype if f.dtype in (np.int32, np.int64) else np.int64)  # as the encoder reads
    k = len(f)
    out = records(k + (-(-(12 * len(v) + 3) // STL_RECORD.itemsize) if scratch else 0))
    return out[:_codec.encode(v, f, 0.0 if grid is None else float(grid), out)]


def _encode(tri: np.ndarray, rec: np.ndarray) -> None:
    """Fill records ``rec`` (k,) from float32 triangles (k, 3, 3)."""
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


class StlWriter:
    """Incremental binary STL: header, then chunks of triangles, then the count is patched.

    Use as a context manager around ``ple.io.files.atomic_path`` output: memory stays bounded
    by the largest chunk, whatever the total."""

    def __init__(self, fh, header: bytes = b"PLE binary STL", direct: bool = True):
        self.fh = fh
        self.count = 0
        self.direct = direct_writer(fh) if direct else None  # a new regular file: past the page cache
        head = header[:80].ljust(80, b" ") + struct.pack("<I", 0)
        if self.direct is not None:
            self.direct.write(head)
        else:
            fh.write(head)
        # else a page cache of about two windows, whatever the file's size
        self.behind = WriteBehind(fh) if self.direct is None else None

    def write(self, triangles: np.ndarray, faces: np.ndarray | None = None) -> None:
        """Append triangles (k, 3, 3), or ``vertices[faces]`` for vertices (V, 3), faces (k, 3)."""
        self.write_records(stl_records(triangles, faces))

    def write_records(self, rec: np.ndarray) -> None:
        """Append records made by ``stl_records``."""
        self.count += len(rec)
        if self.count > STL_MAX_TRIANGLES:
            raise PleError(f"binary STL holds at most {STL_MAX_TRIANGLES} triangles; use a smaller --region")
        if self.direct is not None:
            self.direct.write(memoryview(rec).cast("B"))
            return
        self.fh.write(memoryview(rec).cast("B"))
        self.behind.wrote()

    def close(self) -> None:
        if self.direct is not None:  # its bytes are on disk once it is closed; the count goes through fh
            direct, self.direct = self.direct, None
            direct.close()
        self.fh.seek(80)
        self.fh.write(struct.pack("<I", self.count))
        self.fh.seek(0, 2)

    def abort(self) -> None:
        """Stop without finishing the file (its writer thread, if any, ends)."""
        if self.direct is not None:
            self.direct.abort()
            self.direct = None


def direct_writer(fh) -> DirectWriter | None:
    """A ``DirectWriter`` appending to ``fh`` when it is an empty regular file opened by path,
    with nothing written yet and O_DIRECT allowed there; else None (buffered writes)."""
    try:
        if fh.tell() != 0 or not isinstance(fh.name, (str, bytes)):
            return None
        st = os.fstat(fh.fileno())
        if not stat.S_ISREG(st.st_mode) or st.st_size or not os.path.samestat(st, os.stat(fh.name)):
            return None
        return DirectWriter(fh.name)
    except (OSError, AttributeError, ValueError, io.UnsupportedOperation):
        return None


def stl_header(unit: str = DEFAULT_UNIT, what: str = "binary STL") -> bytes:
    """The 80-byte header of our STL files: it states the unit and the up axis."""
    return f"PLE {what}, unit {unit}, Z up".encode()[:80].ljust(80, b" ")


class RecordPool(ArrayPool):
    """Record buffers handed from written boxes to the next ones (thread-safe). A streamed file
    is written box by box; fresh buffers would cost every box its page faults again (on this
    machine first touches of a box's records took longer than encoding them). At most as many
    buffers as boxes in flight, each as large as the largest box so far. ``give`` takes records
    (or a slice of them) back once written."""

    def take(self, k: int) -> np.ndarray:
        """k uninitialised records."""
        return super().take((k,), STL_RECORD)


def stl_chunk(chunk, grid: float | None = None, pool: RecordPool | None = None) -> np.ndarray:
    """The binary STL records of one chunk: triangles (k, 3, 3) or a pair (vertices (V, 3), faces
    (k, 3)), snapped to the float32 ``grid`` (``ple.meshing.weld``) when given, triangles whose
    corners then coincide dropped. ``pool``: where the records' buffer comes from (give it back
    once written)."""
    if isinstance(chunk, np.ndarray) and chunk.dtype == STL_RECORD:  # encoded already (``iter_triangles(encode=)``)
        return chunk
    records = (lambda k: np.empty(k, STL_RECORD)) if pool is None else pool.take
    if isinstance(chunk, tuple) and _codec is not None:  # compiled: snap, drop and encode in one pass
        return _compiled(chunk[0], chunk[1], grid, records, scratch=pool is not None)
    if isinstance(chunk, tuple):  # in slices of faces: the float32 triangles and normals stay small
        f = np.asarray(chunk[1]).reshape(-1, 3)
        out = records(len(f))
        n = 0
        for tri in snapped_slices(chunk[0], f, grid, ENCODE_SLICE):
            stl_records(tri, out=out[n:n + len(tri)])
            n += len(tri)
        return out[:n]
    tri = np.asarray(chunk, float).reshape(-1, 3, 3)
    return stl_records(snap_triangles(tri, grid) if grid is not None else tri)


def write_stl(path, chunks: Iterable, header: bytes = b"PLE binary STL", grid: float | None = None,
              workers: int = 1, pool: RecordPool | None = None) -> int:
    """Write chunks to binary STL atomically; a chunk is triangles (k, 3, 3) or a pair
    (vertices (V, 3), faces (k, 3)), or records already (``stl_chunk``). With ``grid`` every
    vertex is snapped to that float32 grid (``ple.meshing.weld``; the same grid for every
    chunk) and triangles whose corners then coincide are dropped. ``workers`` threads encode
    chunks at once (numpy releases the GIL), at most workers + 1 held; the file does not depend
    on their number. Record buffers are reused from written chunks (``pool``: the one records
    given as chunks were taken from). Returns the number of triangles."""
    pool = RecordPool() if pool is None else pool
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        w = StlWriter(fh, header)
        try:
            for rec in ordered_map(lambda chunk: stl_chunk(chunk, grid, pool), chunks, workers):
                check_finite_array(rec["vertices"], f"{path}: the mesh")
                w.write_records(rec)
                pool.give(rec)
            w.close()
        finally:
            w.abort()  # after an error: its writer thread ends (the temporary is removed)
    return w.count


def prepare(vertices, faces, fmt: str, unit: str = DEFAULT_UNIT, grid: float | None = None):
    """Vertices and faces as they go into a file of format ``fmt``: in the format's axes and unit
    (``ple.io.formats.to_file_axes``), snapped to the float32 grid and welded
    (``ple.meshing.weld``) so the file reads back with the topology it was checked with.
    ``grid``: the snap grid (default: from these vertices' bounds; ignored for a format with its
    own unit, glTF, whose coordinates are rescaled). Returns (vertices exactly in float32, faces,
    weld stats)."""
    v = to_file_axes(vertices, fmt, unit)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    if MESH_FORMATS[fmt].unit is not None:
        grid = None
    if grid is None:
        grid = grid_spacing(v.min(axis=0), v.max(axis=0)) if len(v) else 1.0
    return weld(v, f, grid)


def encode_mesh(vertices, faces, fmt: str, unit: str = DEFAULT_UNIT) -> bytes:
    """The file contents, in format ``fmt``, of a mesh already ``prepare``d for it."""
    if fmt == "stl":
        rec = stl_records(vertices, faces)
        return stl_header(unit) + np.uint32(len(rec)).tobytes() + rec.tobytes()
    if fmt == "3mf":
        return package_bytes(vertices, faces, unit_name(unit))
    if fmt == "ply":
        return ply_bytes(vertices, faces, unit)
    if fmt == "obj":
        return obj_bytes(vertices, faces, unit)
    import trimesh  # GLB only: the other formats are encoded here

    out = trimesh.Trimesh(np.asarray(vertices, np.float32), faces, process=False)
    return glb_with_targets(trimesh.exchange.gltf.export_glb(out, include_normals=False))


GL_ARRAY_BUFFER, GL_ELEMENT_ARRAY_BUFFER = 34962, 34963


def glb_with_targets(glb: bytes) -> bytes:
    """A GLB whose buffer views state their target (vertex data or indices), as the Khronos glTF
    validator asks (trimesh leaves them out). The binary chunk is kept byte for byte."""
    magic, version, _ = struct.unpack_from("<4sII", glb, 0)
    n, kind = struct.unpack_from("<I4s", glb, 12)
    if magic != b"glTF" or kind != b"JSON":
        raise PleError("not a GLB file")
    doc = json.loads(glb[20:20 + n])
    views = doc.get("bufferViews", [])
    for mesh in doc.get("meshes", []):
        for prim in mesh.get("primitives", []):
            for acc in prim.get("attributes", {}).values():
                views[doc["accessors"][acc]["bufferView"]]["target"] = GL_ARRAY_BUFFER
            if "indices" in prim:
                views[doc["accessors"][prim["indices"]]["bufferView"]]["target"] = GL_ELEMENT_ARRAY_BUFFER
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)  # chunks are 4-byte aligned, JSON padded with spaces
    rest = glb[20 + n:]
    head = struct.pack("<4sII", b"glTF", version, 12 + 8 + len(text) + len(rest))
    return head + struct.pack("<I4s", len(text), b"JSON") + text + rest


def export_mesh(mesh: trimesh.Trimesh, path, unit: str = DEFAULT_UNIT, grid: float | None = None) -> dict:
    """Write a mesh; the format follows the suffix. Coordinates are in ``unit`` (default mm:
    written into 3MF, stated in the STL header, PLY and OBJ comments; glTF is converted to
    metres, its unit). glTF and OBJ are Y-up (converted from our Z-up). Coordinates are
    snapped to float32 and welded first (``prepare``); returns the weld statistics."""
    fmt = mesh_format(path)
    unit_name(unit)
    check_finite_array(mesh.vertices, f"{path}: the mesh")
    v, f, stats = prepare_closed(mesh, fmt, unit, grid, Path(path).name)
    data = encode_mesh(v, f, fmt, unit)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return stats


def prepare_closed(mesh: trimesh.Trimesh, fmt: str, unit: str = DEFAULT_UNIT, grid: float | None = None,
                   name: str = "the mesh") -> tuple[np.ndarray, np.ndarray, dict]:
    """``prepare`` for a closed mesh that must stay closed in the file: edges of a few float32
    steps (a Boolean's slivers) that pinch when snapped are collapsed in 64 bits first (link
    condition: the mesh stays a closed 2-manifold), then snapped again; a mesh that still does
    not close is refused (PleError naming ``name``)."""
    v, f, stats = prepare(mesh.vertices, mesh.faces, fmt, unit, grid)
    if len(f) and edge_manifold(f)["bad_edges"] and not edge_manifold(mesh.faces)["bad_edges"]:
        verts, faces = shortened(mesh.vertices, mesh.faces)
        v, f, stats = prepare(verts, faces, fmt, unit, grid)
    if len(f) and edge_manifold(f)["bad_edges"] and not edge_manifold(mesh.faces)["bad_edges"]:
        shortest = float(mesh.edges_unique_length.min())
        if shortest > 0:  # a zero-length edge is a degenerate mesh, not a range float32 cannot hold
            check_float32_range(mesh.vertices, shortest, fmt)
        why = " (zero-length edges: degenerate triangles, e.g. of a self-intersecting body)" if shortest <= 0 else ""
        raise PleError(f"{name}: the closed mesh does not stay closed in {fmt}'s float32 coordinates{why}")
    return v, f, stats


def shortened(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """A closed mesh with its edges shorter than ``COLLAPSE_GRIDS`` float32 steps at its size
    collapsed (``ple.meshing.weld.collapse_short_edges``); unreferenced vertices dropped."""
    v = np.asarray(vertices, float)
    g = grid_spacing(v.min(axis=0), v.max(axis=0))
    f, _, _ = collapse_short_edges(v, faces, [], COLLAPSE_GRIDS * g)
    used = np.unique(f)
    remap = np.full(len(v), -1, np.int64)
    remap[used] = np.arange(len(used))
    return v[used], remap[f]


MIN_FEATURE_GRIDS = 16  # the smallest ball radius, in float32 grid steps, that a written mesh keeps closed


def check_float32_range(vertices_or_bounds, smallest: float, fmt: str) -> None:
    """Refuse a mesh whose features (``smallest``: a ball radius or an edge, world units) are
    finer than float32 can place at its largest coordinate: written, it would not be closed
    (a similarity scaled by 1e10 puts groups of size 1 beside groups of size 1e10).
    The tolerance is relative: the float32 grid at the mesh's own size (``grid_spacing``)."""
    b = np.asarray(vertices_or_bounds, float).reshape(-1, 3)
    g = grid_spacing(b.min(axis=0), b.max(axis=0))
    if not smallest >= MIN_FEATURE_GRIDS * g:
        size = float(np.max(np.abs(b)))
        raise PleError(f"features of {smallest:.3g} beside coordinates of {size:.3g}: {fmt}'s float32 "
                       f"coordinates step by {g:.3g} there, too coarse to keep the mesh closed "
                       f"(mesh a region with a smaller range of sizes, or shrink the lattice's scale factors)")


def mesh_bytes(mesh: trimesh.Trimesh, fmt: str, unit: str = DEFAULT_UNIT, grid: float | None = None) -> bytes:
    """The file contents of a mesh in format ``fmt``, as ``export_mesh`` writes them (for writers
    to other places: job parts)."""
    format_named(fmt)
    unit_name(unit)
    v, f, _ = prepare(mesh.vertices, mesh.faces, fmt, unit, grid)
    return encode_mesh(v, f, fmt, unit)


def read_back(path, unit: str = DEFAULT_UNIT, as_stored: bool = False) -> trimesh.Trimesh:
    """A written mesh file as a consumer reads it: equal coordinates merged into one vertex, in
    PLE's axes and ``unit`` again (``ple.io.formats.from_file_axes``; ``as_stored``: the file's
    own coordinates, as a consumer checks them); vertices no face uses (a beam-lattice 3MF also
    lists the ball centres) are dropped."""
    import trimesh
    fmt = mesh_format(path)
    m = trimesh.load(path, force="mesh", process=False)
    v = np.asarray(m.vertices, float)
    first, inv, _ = unique_rows(v)
    uniq, f = v[first], inv[np.asarray(m.faces)]
    out = trimesh.Trimesh(uniq if as_stored else from_file_axes(uniq, fmt, unit), f, process=False)
    out.remove_unreferenced_vertices()
    return out


def ply_bytes(vertices, faces, unit: str = DEFAULT_UNIT) -> bytes:
    """Binary little-endian PLY: float32 vertices, uchar-counted int32 faces; unit in a comment."""
    v = np.ascontiguousarray(vertices, "<f4")
    rec = np.empty(len(faces), np.dtype([("n", "u1"), ("f", "<i4", (3,))]))
    rec["n"] = 3
    rec["f"] = faces
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"comment PLE lattice mesh, unit {unit}, Z up\n"
              f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(rec)}\nproperty list uchar int vertex_indices\nend_header\n")
    return header.encode() + v.tobytes() + rec.tobytes()


def obj_bytes(vertices, faces, unit: str = DEFAULT_UNIT) -> bytes:
    """Wavefront OBJ (Y up, 9 significant digits: float32 values exactly); unit in a comment."""
    buf = io.StringIO()
    buf.write(f"# PLE lattice mesh, unit {unit}, Y up\n")
    if len(vertices):
        np.savetxt(buf, np.asarray(vertices, np.float32).astype(float), fmt="v %.9g %.9g %.9g")
    if len(faces):
        np.savetxt(buf, np.asarray(faces, np.int64) + 1, fmt="f %d %d %d")
    return buf.getvalue().encode()


def write_beam_lattice_3mf(path, center, radius, beam_nodes, mesh=None, unit: str = DEFAULT_UNIT) -> None:
    """A 3MF package with the Beam Lattice extension (balls and cone beams). With ``mesh``
    (the lattice's watertight triangle mesh) the same object carries its triangles and the
    extensions are not required, so consumers without beam support print the triangles;
    without it the file holds beams only and requires the extensions."""
    if mesh_format(path) != "3mf":
        raise PleError(f"{path}: a beam lattice is written as .3mf")
    if mesh is None:
        v, f = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    else:
        v, f, _ = prepare_closed(mesh, "3mf", unit, name=Path(path).name)
    write_3mf(path, v, f, unit_name(unit), (center, radius, beam_nodes))
