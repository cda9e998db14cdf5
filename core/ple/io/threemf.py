"""Our own strict 3MF writer: triangle meshes, and triangle meshes with a Beam Lattice.

One model part (3D/3dmodel.model) with one mesh object and one build item; namespaces are
declared once, on ``<model>``; the unit is the model's ``unit`` attribute. Coordinates are
written with 9 significant digits, which reproduces a float32 exactly (callers pass vertices
already snapped to a float32 grid, ``ple.meshing.weld``), so lib3mf — which stores float32 — reads
back the very mesh that was checked.

With a lattice (3MF Beam Lattice extension 1.2 and its balls extension), the same mesh object
holds the triangle mesh of the lattice *and* a ``b:beamlattice`` of its balls and cone beams,
whose vertices follow the mesh's. The extensions are declared but not required: a consumer
without beam support prints the triangles, one with it the union of triangles and beams, which
is the same solid.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np

from ..errors import PleError, echo
from .files import atomic_path

NS_CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"
NS_BEAM = "http://schemas.microsoft.com/3dmanufacturing/beamlattice/2017/02"
NS_BALLS = "http://schemas.microsoft.com/3dmanufacturing/beamlattice/balls/2020/07"
UNITS_3MF = ("micron", "millimeter", "centimeter", "inch", "foot", "meter")
CONTENT_TYPES = ('<?xml version="1.0" encoding="UTF-8"?>\n'
                 '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
                 '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
                 '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
                 '</Types>\n')
RELS = ('<?xml version="1.0" encoding="UTF-8"?>\n'
        '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
        '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
        'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>\n')


ROWS = 1 << 16  # vertices, triangles, beams or balls formatted at a time: the text of a slice, never of a mesh


def _write_rows(fh, fmt: str, a: np.ndarray) -> None:
    """``fmt`` (one row's XML element) for each row of ``a``, ROWS rows formatted by one ``%``
    (``np.savetxt``'s text, without its Python call and write per row)."""
    for k in range(0, len(a), ROWS):
        rows = a[k:k + ROWS]
        fh.write((fmt * len(rows)) % tuple(rows.ravel().tolist()))


def write_model(fh, vertices: np.ndarray, faces: np.ndarray, unit: str = "millimeter", lattice=None,
                name: str = "PLE lattice") -> None:
    """Write the 3D model part to the text stream ``fh``, ``ROWS`` rows at a time (the XML of a
    large mesh is never one string). ``vertices`` (V, 3) (float32 values), ``faces`` (F, 3) outward;
    ``lattice``: None or (center (B, 3), radius (B,), beam_nodes (E, 2)) for a Beam Lattice."""
    if unit not in UNITS_3MF:
        raise PleError(f"3MF unit {echo(unit)}: expected one of {', '.join(UNITS_3MF)}")
    v = np.asarray(vertices, np.float32).reshape(-1, 3)
    f = np.asarray(faces).reshape(-1, 3)
    if not np.all(np.isfinite(v)):
        raise PleError("3MF: vertex coordinates must be finite")
    if len(f) and (f.min() < 0 or f.max() >= len(v)):
        raise PleError("3MF: a triangle refers to a missing vertex")
    if not len(f) and lattice is None:
        raise PleError("3MF: the mesh has no triangles")
    ns = f'xmlns="{NS_CORE}"'
    if lattice is not None:
        lattice = _check_lattice(*lattice)
        ns += f' xmlns:b="{NS_BEAM}" xmlns:b2="{NS_BALLS}"'
    required = ' requiredextensions="b b2"' if lattice is not None and not len(f) else ""
    fh.write(f'<?xml version="1.0" encoding="UTF-8"?>\n'
             f'<model {ns} unit="{unit}" xml:lang="en-US"{required}>'
             f'<metadata name="Application">PLE, the Programmed Lattice Editor</metadata>'
             f'<resources><object id="1" type="model" name="{name}"><mesh><vertices>')
    vertex = '<vertex x="%.9g" y="%.9g" z="%.9g"/>'
    _write_rows(fh, vertex, v.astype(float))
    if lattice is not None:  # the balls' centres follow the mesh's vertices
        _write_rows(fh, vertex, lattice[0].astype(np.float32).astype(float))
    fh.write("</vertices><triangles>")
    _write_rows(fh, '<triangle v1="%d" v2="%d" v3="%d"/>', f)
    fh.write("</triangles>")
    if lattice is not None:
        _write_beamlattice(fh, len(v), *lattice)
    fh.write("</mesh></object></resources><build><item objectid=\"1\"/></build></model>\n")


def _check_lattice(center, radius, beam_nodes):
    center = np.asarray(center, float).reshape(-1, 3)
    radius = np.asarray(radius, float).reshape(-1)
    beam_nodes = np.asarray(beam_nodes, np.int64).reshape(-1, 2)
    if len(center) == 0:
        raise PleError("beam lattice 3MF: the region has no balls")
    if len(radius) != len(center) or not (np.all(np.isfinite(center)) and np.all(radius > 0)):
        raise PleError("beam lattice 3MF: ball centres must be finite and radii positive")
    if len(beam_nodes) and (beam_nodes.min() < 0 or beam_nodes.max() >= len(center)):
        raise PleError("beam lattice 3MF: a beam refers to a missing ball")
    return center, radius, beam_nodes


def _write_beamlattice(fh, offset: int, center, radius, beam_nodes) -> None:
    """b:beamlattice of cone beams (r1, r2 = the end balls' radii) and b2:balls at every ball
    (ball mode ``mixed``); vertex ids start at ``offset`` (after the triangle mesh's)."""
    c32 = np.asarray(center, np.float32).astype(float)
    lengths = np.linalg.norm(c32[beam_nodes[:, 0]] - c32[beam_nodes[:, 1]], axis=1) if len(beam_nodes) else []
    min_length = max(1e-9, 0.5 * float(np.min(lengths))) if len(beam_nodes) else 1e-4
    default_r = float(np.median(radius))
    beams = np.column_stack([beam_nodes + offset, radius[beam_nodes[:, 0]], radius[beam_nodes[:, 1]]]) \
        if len(beam_nodes) else np.zeros((0, 4))
    fh.write(f'<b:beamlattice minlength="{min_length:.9g}" radius="{default_r:.17g}" clippingmode="none" '
             f'cap="sphere" b2:ballmode="mixed" b2:ballradius="{default_r:.17g}"><b:beams>')
    _write_rows(fh, '<b:beam v1="%d" v2="%d" r1="%.17g" r2="%.17g"/>', beams)
    fh.write("</b:beams><b2:balls>")
    _write_rows(fh, '<b2:ball vindex="%d" r="%.17g"/>', np.column_stack([np.arange(len(radius)) + offset, radius]))
    fh.write("</b2:balls></b:beamlattice>")


def _write_package(target, vertices, faces, unit: str, lattice) -> None:
    """The 3MF package (a zip) into ``target`` (a path or a binary stream); the model part is
    streamed into its zip entry (``write_model``)."""
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("[Content_Types].xml", CONTENT_TYPES)
        z.writestr("_rels/.rels", RELS)
        with z.open("3D/3dmodel.model", "w", force_zip64=True) as raw, \
                io.TextIOWrapper(raw, encoding="utf-8", newline="") as fh:
            write_model(fh, vertices, faces, unit, lattice)


def package_bytes(vertices, faces, unit: str = "millimeter", lattice=None) -> bytes:
    """The bytes of a 3MF package (see ``write_model``): for writers to other places (job parts)."""
    buf = io.BytesIO()
    _write_package(buf, vertices, faces, unit, lattice)
    return buf.getvalue()


def write_3mf(path, vertices, faces, unit: str = "millimeter", lattice=None) -> None:
    """Write a 3MF package atomically (see ``write_model``), streamed: the file holds the text,
    memory a slice of it."""
    with atomic_path(path) as tmp:
        _write_package(tmp, vertices, faces, unit, lattice)
