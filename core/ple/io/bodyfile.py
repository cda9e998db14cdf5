"""Body mesh files (STL, OBJ, PLY, 3MF, GLB) read into a :class:`ple.filters.body.Body`.

Triangles of a file are merged at shared vertices (an STL stores each triangle's corners apart)
and, when the surface is closed but some faces point the other way, re-oriented consistently;
every other defect is named: a missing or unreadable file, an empty mesh, NaN vertices, a hole."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..algebra.similarity import Similarity
from ..errors import PleError, echo
from ..filters.body import Body
from .inputs import check_input_file

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh

BODY_SUFFIXES = ("stl", "obj", "ply", "3mf", "glb", "gltf", "off")
MAX_BODY_TRIANGLES = 20_000_000
MAX_BODY_BYTES = 1 << 30  # a binary STL of 20 M triangles; read whole by trimesh, so checked first


def load_body(path, placement: Similarity | None = None, open: str = "error", name: str | None = None) -> Body:  # noqa: A002
    """The body in mesh file ``path``, placed by ``placement``."""
    return body_from_trimesh(read_mesh(path, name), placement, str(path), open, name or str(path))


def read_mesh(path, name: str | None = None) -> trimesh.Trimesh:
    """The triangles of mesh file ``path`` (STL, OBJ, PLY, 3MF, GLB, OFF), read within limits: a
    regular file of at most 1 GiB, at most 20 M triangles, finite vertices; every failure of the
    reader is one error naming the file (``name``: how the user gave it, e.g. ``--body F``)."""
    import trimesh
    path = Path(path)
    name = name or str(path)
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in BODY_SUFFIXES:
        raise PleError(f"{name}: unknown body mesh format {echo(suffix)} (expected .{', .'.join(BODY_SUFFIXES)})")
    try:  # a regular file within the limit: a folder, FIFO (would block) or device is named as such
        check_input_file(path, "body mesh file", MAX_BODY_BYTES)
    except PleError as exc:
        raise PleError(f"{name}: {str(exc).removeprefix(str(path) + ': ')}") from None
    if suffix == "stl":
        check_stl_count(path, name)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad file, named
        raise PleError(f"{name}: cannot read the body mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise PleError(f"{name}: the mesh is empty (no triangles)")
    if len(mesh.faces) > MAX_BODY_TRIANGLES:
        raise PleError(f"{name}: {len(mesh.faces):,} triangles (limit {MAX_BODY_TRIANGLES:,})")
    v = np.asarray(mesh.vertices, dtype=float)
    bad = int(np.count_nonzero(~np.isfinite(v).all(axis=1))) if v.ndim == 2 else 0
    if bad:
        raise PleError(f"{name}: {bad} of {len(v)} vertices are NaN or infinite")
    f = np.asarray(mesh.faces)
    if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= len(v):
        raise PleError(f"{name}: a face refers to vertex {int(f.max() if f.max() >= len(v) else f.min())}, "
                       f"outside the {len(v)} vertices; the file is damaged")
    return mesh


MERGE_DIGITS = 1e8  # vertices closer than 1e-8 of the mesh's size are one vertex


def merged_vertices(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3) with the vertices that coincide within 1e-8 of the mesh's
    size merged (an STL stores each triangle's corners apart). The tolerance is relative, computed
    in a frame scaled to the mesh, so a body of size 1e30 merges as one of size 1 (an absolute
    rounding overflows there); the kept vertices keep their exact coordinates."""
    if not len(v):
        return v, f
    lo, hi = v.min(axis=0), v.max(axis=0)
    scale = float((hi - lo).max()) or 1.0
    keys = np.round((v - (lo + hi) / 2) / scale * MERGE_DIGITS).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return v[first], inverse.reshape(-1)[f]


def check_stl_count(path: Path, name: str) -> None:
    """A binary STL's header counts its triangles: a count that its size contradicts (a truncated
    or damaged file) is named, not read as an empty or shortened mesh. ASCII STL passes."""
    with open(path, "rb") as fh:
        head = fh.read(1024)
    size = path.stat().st_size
    if head.lstrip().startswith(b"solid") and (b"facet" in head or b"endsolid" in head):
        return  # ASCII
    if size < 84:
        return  # too short for a binary STL: trimesh's reader names it (empty)
    count = int.from_bytes(head[80:84], "little")
    if 84 + 50 * count != size:
        raise PleError(f"{name}: a binary STL whose header counts {count:,} triangles, but whose size "
                       f"({size:,} bytes) holds {(size - 84) / 50:,.6g}; the file is truncated or damaged")


def surface(mesh, name: str = "body") -> tuple[trimesh.Trimesh, bool]:
    """The one preparation of a read mesh, for bodies and fits alike: vertices merged within a
    tolerance relative to its size (``merged_vertices``), and a closed surface whose faces point
    both ways oriented consistently. Returns the surface and whether the file's own orientation
    was consistent (then a negative volume means the file is inside out, ``inverted``)."""
    import trimesh
    v = np.asarray(mesh.vertices, dtype=float)
    bad = int(np.count_nonzero(~np.isfinite(v).all(axis=1))) if v.ndim == 2 else 0
    if bad:
        raise PleError(f"{name}: {bad} of {len(v)} vertices are NaN or infinite")
    v, f = merged_vertices(v, np.asarray(mesh.faces))
    out = trimesh.Trimesh(v, f, process=False)
    consistent = bool(out.is_winding_consistent)
    if out.is_watertight and not consistent:
        trimesh.repair.fix_winding(out)
    return out, consistent


def signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """The signed volume of triangles ``f`` (F, 3) of vertices ``v`` (V, 3), in a frame centred and
    scaled to the mesh (no overflow at 1e100, no underflow at 1e-100): positive when the faces
    point outward."""
    lo, hi = v.min(axis=0), v.max(axis=0)
    scale = float((hi - lo).max()) or 1.0
    tri = ((v - (lo + hi) / 2) / scale)[f]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0) * scale ** 3


def closed_mesh(path, name: str | None = None, flip: bool = False,
                flag: str = "--flip") -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3) of a closed mesh file enclosing a volume, outward
    (``read_mesh`` and ``surface``): a one-point, open or flat mesh is refused, and so is an
    inverted one (consistently oriented, negative volume: inside out) unless ``flip`` reverses
    its faces (``flag`` names the option that does)."""
    name = name or str(path)
    mesh, consistent = surface(read_mesh(path, name), name)
    v, f = np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)
    extent = float((v.max(axis=0) - v.min(axis=0)).max())
    if not extent > 0:
        raise PleError(f"{name}: all its vertices are one point; it encloses nothing")
    if not mesh.is_watertight:
        _, uses = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
        raise PleError(f"{name}: not closed ({int(np.count_nonzero(uses != 2)):,} edges not shared by exactly "
                       "two triangles); a closed mesh is needed")
    volume = signed_volume(v, f)
    if not abs(volume) > 1e-9 * extent ** 3:
        raise PleError(f"{name}: encloses no volume (flat); a closed mesh around a volume is needed")
    if volume < 0:
        if consistent and not flip:
            raise PleError(f"{name}: the mesh is inverted (inside out: its faces point inward, volume "
                           f"{volume:.6g}); pass {flag} to reverse them, or flip its normals in the modeller")
        f = f[:, ::-1].copy()
    return v, f


def body_from_trimesh(mesh, placement: Similarity | None = None, source: str | None = None,
                      open: str = "error", name: str = "body") -> Body:  # noqa: A002
    """A Body from a trimesh mesh: vertices merged, a closed surface oriented consistently
    (``surface``; Body turns an inside-out surface outward)."""
    mesh, _ = surface(mesh, name)
    return Body(mesh.vertices, mesh.faces, placement, source, open, name)
