"""Mesh and lattice files: binary STL (own numpy writer, streaming), PLY, OBJ, GLB, 3MF via
trimesh, 3MF with the Beam Lattice extension (balls and beams, no triangles), meshes of
lattice regions written straight to a file, and BeCOTS connector sets.

Every write is atomic (``ple.io.files.atomic_path``): on any error no partial file is left.
"""

from __future__ import annotations

import json
import struct
import zipfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import trimesh

from ..errors import PleError
from ..meshing.connectors import constant_radius_connectors
from ..meshing.tessellate import iter_triangles, tessellate, weld_chunks
from ..model.lattice import Lattice
from .files import atomic_path, atomic_write_text, check_output_dir, write_marker
from .formats import format_named, mesh_format

STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
STL_MAX_TRIANGLES = 2**32 - 1
NS_CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
NS_BEAM = "http://schemas.microsoft.com/3dmanufacturing/beamlattice/2017/02"
NS_BALLS = "http://schemas.microsoft.com/3dmanufacturing/beamlattice/balls/2020/07"


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


def write_stl(path, chunks: Iterable) -> int:
    """Write chunks to binary STL atomically; a chunk is triangles (k, 3, 3) or a pair
    (vertices (V, 3), faces (k, 3)). Returns the number of triangles."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        w = StlWriter(fh)
        for chunk in chunks:
            if isinstance(chunk, tuple):
                w.write(*chunk)
            else:
                w.write(chunk)
        w.close()
    return w.count


def export_mesh(mesh: trimesh.Trimesh, path) -> None:
    """Write a mesh; the format follows the suffix (.stl by our writer, others by trimesh)."""
    fmt = mesh_format(path)
    if fmt == "stl":
        write_stl(path, [np.asarray(mesh.triangles)])
        return
    with atomic_path(path) as tmp:
        tmp.write_bytes(mesh_bytes(mesh, fmt))


def write_chunks(path, chunks: Iterable) -> int:
    """Write the boxes of ``iter_triangles`` (pairs vertices, faces) as one mesh, welded by
    ``weld_chunks``, in the format of ``path``'s suffix; returns the number of triangles. (Binary
    STL needs no weld: ``write_stl`` streams the boxes.)"""
    verts, faces = weld_chunks(chunks)
    export_mesh(trimesh.Trimesh(verts, faces, process=False), path)
    return len(faces)


def mesh_bytes(mesh: trimesh.Trimesh, fmt: str) -> bytes:
    """The file contents of a mesh in format ``fmt`` (for writers to other places: job parts)."""
    if format_named(fmt) == "stl":
        rec = stl_records(np.asarray(mesh.vertices), np.asarray(mesh.faces))
        return b"PLE mesh".ljust(80, b" ") + np.uint32(len(rec)).tobytes() + rec.tobytes()
    data = trimesh.exchange.export.export_mesh(mesh, None, file_type=fmt)
    return data if isinstance(data, bytes) else data.encode()


def beam_lattice_model_xml(center: np.ndarray, radius: np.ndarray, beam_nodes: np.ndarray,
                           unit: str = "millimeter") -> str:
    """3D/3dmodel.model text: one object whose mesh holds the ball centres as vertices, a
    b:beamlattice of cone beams (r1, r2 = the end balls' radii) and b2:balls at every vertex."""
    center = np.asarray(center, float).reshape(-1, 3)
    radius = np.asarray(radius, float).reshape(-1)
    beam_nodes = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    if len(center) == 0:
        raise PleError("beam lattice 3MF: the region has no balls")
    if not (np.all(np.isfinite(center)) and np.all(radius > 0)):
        raise PleError("beam lattice 3MF: ball centres must be finite and radii positive")
    lengths = np.linalg.norm(center[beam_nodes[:, 0]] - center[beam_nodes[:, 1]], axis=1) if len(beam_nodes) else []
    min_length = max(1e-9, 0.5 * float(np.min(lengths))) if len(beam_nodes) else 1e-4
    default_r = float(np.median(radius))
    fmt = lambda a: np.char.mod("%.9g", a)  # noqa: E731
    cx, cy, cz = fmt(center[:, 0]), fmt(center[:, 1]), fmt(center[:, 2])
    verts = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for x, y, z in zip(cx, cy, cz))
    r = fmt(radius)
    beams = "".join(f'<b:beam v1="{a}" v2="{b}" r1="{r[a]}" r2="{r[b]}"/>' for a, b in beam_nodes)
    balls = "".join(f'<b2:ball vindex="{i}" r="{ri}"/>' for i, ri in enumerate(r))
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<model xmlns="{NS_CORE}" xmlns:b="{NS_BEAM}" xmlns:b2="{NS_BALLS}" unit="{unit}" '
            f'xml:lang="en-US" requiredextensions="b b2">'
            f'<resources><object id="1" type="model" name="PLE lattice"><mesh>'
            f'<vertices>{verts}</vertices>'
            f'<b:beamlattice minlength="{min_length:.9g}" radius="{default_r:.9g}" clippingmode="none" '
            f'cap="sphere" b2:ballmode="mixed" b2:ballradius="{default_r:.9g}">'
            f'<b:beams>{beams}</b:beams><b2:balls>{balls}</b2:balls></b:beamlattice>'
            f'</mesh></object></resources><build><item objectid="1"/></build></model>\n')


CONTENT_TYPES = ('<?xml version="1.0" encoding="UTF-8"?>\n'
                 '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
                 '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
                 '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
                 '</Types>\n')
RELS = ('<?xml version="1.0" encoding="UTF-8"?>\n'
        '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
        '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
        'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>\n')


def write_beam_lattice_3mf(path, center, radius, beam_nodes) -> None:
    """A 3MF package with the Beam Lattice extension (balls and beams, no triangles)."""
    if mesh_format(path) != "3mf":
        raise PleError(f"{path}: a beam lattice is written as .3mf")
    model = beam_lattice_model_xml(center, radius, beam_nodes)
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("[Content_Types].xml", CONTENT_TYPES)
        z.writestr("_rels/.rels", RELS)
        z.writestr("3D/3dmodel.model", model)


def write_mesh(lat: Lattice, path, style: str = "refined", region=None, levels: int | None = None,
               segments: int | None = None, max_groups: int = 1 << 14, fillet: float | None = None) -> int:
    """Tessellate a region straight to ``path`` (format from the suffix); returns the number of
    triangles. Binary STL streams box by box (memory bounded by ``max_groups`` groups); the
    other formats build the mesh in memory and go through trimesh."""
    if mesh_format(path) == "stl":
        return write_stl(path, iter_triangles(lat, region, style, levels, segments, max_groups, fillet=fillet))
    mesh = tessellate(lat, region, style, levels, segments, fillet=fillet)
    export_mesh(mesh, path)
    return len(mesh.faces)


def export_connectors(lat: Lattice, folder, radius: float, beam_radius: float | None = None,
                      grow: float = 0.5, region=None) -> dict:
    """Write one mesh per connector class (``connector_<n>.stl``), the beams as constant-
    radius cylinders (``beams.stl``) and ``connectors.json`` (class keys, instance motions)."""
    folder = Path(folder)
    check_output_dir(folder, "ple-connectors")  # ours, new or empty: never another folder's files
    classes, beams = constant_radius_connectors(lat, radius, beam_radius, grow, region)
    folder.mkdir(exist_ok=True)
    write_marker(folder, "ple-connectors", "ple becots connectors")
    summary = {"classes": [], "beams": len(beams["start"]), "radius": radius, "beam_radius": beams["radius"]}
    for n, cls in enumerate(classes):
        path = folder / f"connector_{n}.stl"
        with atomic_path(path) as tmp:
            cls.mesh.export(tmp, file_type="stl")
        summary["classes"].append({"file": path.name, "node": cls.key[0], "ends": [list(e) for e in cls.key[1]],
                                   "count": len(cls.instances), "nodes": cls.nodes.tolist(),
                                   "motions": cls.instances.round(12).tolist()})
    cyl = []
    for a, b in zip(beams["start"], beams["end"]):
        if np.linalg.norm(b - a) > 1e-12:
            cyl.append(trimesh.creation.cylinder(radius=beams["radius"], segment=np.stack([a, b]), sections=12))
    if cyl:
        with atomic_path(folder / "beams.stl") as tmp:
            trimesh.util.concatenate(cyl).export(tmp, file_type="stl")
    atomic_write_text(folder / "connectors.json", json.dumps(summary) + "\n")
    return summary
