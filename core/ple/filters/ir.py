"""Filters as data in ``ple-lattice/1`` (the optional ``"filter"`` field; docs/formats.md): stencils,
Lattice-in-Lattice (the coarse lattice inline, itself possibly filtered), implicit TPMS and
Fourier fields, and their and/or/not compounds. Data only: loading never runs code, and every
malformed field is named by its path (``filter.and[1].lil.coarse.nodes[0].radius``)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..algebra.similarity import Similarity, similarity_from_dict
from ..errors import PleError, cut, echo
from ..model.grading import grade_to_dict
from ..model.ir import lattice_from_dict, lattice_to_dict
from ..model.lattice import Lattice
from .base import And, Filter, Not, Or
from .body import MODES, OPEN_MODES, BodyFilter, SurfaceDistanceField, body_filters, body_of
from .cleanup import Cleanup
from .implicit import TPMS, VARIANTS, FourierField, ImplicitFilter, TPMSField
from .lil import LiL
from .stencil import Stencil

MAX_DEPTH = 32  # nesting of and/or/not and LiL coarse lattices
MAX_STENCIL_CELLS = 1 << 20
MAX_FOURIER_TERMS = 1 << 16


def lattice_from_ir(data, loader=None) -> Lattice:
    """A Lattice from ``ple-lattice/1`` data, with its filter. ``loader(path, placement, open,
    where)`` reads a body's mesh file (``ple.io.irfile`` gives one resolving paths against the
    JSON file); without it a body filter is refused."""
    return lattice_from_dict(data, lambda d, w: filter_from_dict(d, w, 0, loader), _surface_grade)


def lattice_to_ir(lat: Lattice, resolved: bool = True, base=None) -> dict:
    """The ``ple-lattice/1`` data of a lattice, with its filter and its grade; body mesh paths
    are written relative to the folder ``base`` when given (the JSON file's), else as they were
    loaded."""
    return lattice_to_dict(lat, resolved, lambda f: filter_to_dict(f, base), lambda g: _grade_to_dict(lat, g))


# ----- grades by the distance to the body's surface -------------------------------------------------
def _surface_grade(lat: Lattice, depth: float, f_surface: float, f_deep: float, where: str):
    """A surface grade of the data: by the distance to the lattice's own body (its body filter)."""
    try:
        body = body_of(lat, where)
    except PleError:
        raise PleError(f"{where}: a surface grade needs a body filter (filter.body) in the same file") from None
    return SurfaceDistanceField(body, depth, f_surface, f_deep)


def _grade_to_dict(lat: Lattice, field) -> dict:
    if isinstance(field, SurfaceDistanceField):
        found = [f.body for f in body_filters(lat)]
        if not found or field.body is not found[-1]:
            raise PleError("grade: a surface grade is written only by the distance to the lattice's own body "
                           "(its body filter)")
        return {"kind": "surface", "depth": field.depth, "f_surface": field.f_surface, "f_deep": field.f_deep}
    return grade_to_dict(field)


# ----- writing -------------------------------------------------------------------------------------
def filter_to_dict(f, base=None) -> dict:
    """The data of a filter; a filter that is not data (a Python object of a program's own) is
    refused naming its type."""
    if isinstance(f, BodyFilter):
        return {"body": _body_to_dict(f, base)}
    if isinstance(f, Cleanup):
        out = {"largest": f.largest}
        if f.part is not None:
            out["filter"] = filter_to_dict(f.part, base)
        if f.skin is not None:
            out["skin"] = f.skin
        return {"cleanup": out}
    if isinstance(f, Stencil):
        a = f.array
        return {"stencil": {"shape": list(a.shape), "cells": a.reshape(-1).astype(int).tolist()}}
    if isinstance(f, LiL):
        return {"lil": {"coarse": lattice_to_ir(f.coarse, base=base), "method": f.method}}
    if isinstance(f, ImplicitFilter):
        return {"implicit": {**_field_to_dict(f.field), "level": f.level, "sheet": f.variant == "sheet"}}
    if isinstance(f, (And, Or)):
        return {"and" if isinstance(f, And) else "or": [filter_to_dict(p, base) for p in f.parts]}
    if isinstance(f, Not):
        return {"not": filter_to_dict(f.part, base)}
    raise PleError(f"filter: a {type(f).__name__} cannot be written as data (stencil, lil, implicit, "
                   "body, cleanup, and, or, not can)")


def _field_to_dict(field) -> dict:
    cell = field.cell.tolist() if field.cell.ndim else float(field.cell)
    out = {"cell": cell}
    if not field.placement.allclose(Similarity(), 0.0):
        out["placement"] = field.placement.to_dict()
    if isinstance(field, TPMSField):
        return {"kind": field.kind, **out}
    if isinstance(field, FourierField):
        return {"kind": "fourier", **out, "n": field.n, "symmetric": field.symmetric,
                "freqs": field.freqs.tolist(), "coeffs": [[float(c.real), float(c.imag)] for c in field.coeffs]}
    raise PleError(f"filter.implicit: a {type(field).__name__} field cannot be written as data")


# ----- reading -------------------------------------------------------------------------------------
def filter_from_dict(data, where: str = "filter", depth: int = 0, loader=None) -> Filter:
    """The filter described by ``data``; errors name the offending field. ``loader`` reads body
    mesh files (see ``lattice_from_ir``)."""
    if depth > MAX_DEPTH:
        raise PleError(f"{where}: filters nested deeper than {MAX_DEPTH}")
    if not isinstance(data, dict) or len(data) != 1:
        raise PleError(f"{where}: expected an object with exactly one of stencil, lil, implicit, body, cleanup, "
                       "and, or, not")
    (kind, body), = data.items()
    here = f"{where}.{kind}"
    if kind in ("and", "or"):
        if not isinstance(body, list) or not body:
            raise PleError(f"{here}: expected a non-empty list of filters")
        parts = [filter_from_dict(p, f"{here}[{n}]", depth + 1, loader) for n, p in enumerate(body)]
        return parts[0] if len(parts) == 1 else (And if kind == "and" else Or)(*parts)
    if kind == "not":
        return Not(filter_from_dict(body, here, depth + 1, loader))
    if kind == "stencil":
        return _stencil(body, here)
    if kind == "lil":
        return _lil(body, here, depth, loader)
    if kind == "implicit":
        return _implicit(body, here)
    if kind == "body":
        return _body(body, here, loader)
    if kind == "cleanup":
        _keys(body, here, set(), {"filter", "largest", "skin"})
        largest, skin = body.get("largest", True), body.get("skin")
        if not isinstance(largest, bool):
            raise PleError(f"{here}.largest: expected true or false, got {echo(largest)}")
        if skin is not None and _number(skin, f"{here}.skin") <= 0:
            raise PleError(f"{here}.skin: must be positive, got {echo(skin)}")
        part = filter_from_dict(body["filter"], f"{here}.filter", depth + 1, loader) if "filter" in body else None
        return Cleanup(part, largest, skin)
    raise PleError(f"{here}: unknown filter (expected stencil, lil, implicit, body, cleanup, and, or, not)")


def _keys(body, here: str, required: set, optional: set = frozenset()) -> None:
    if not isinstance(body, dict):
        raise PleError(f"{here}: expected an object with {', '.join(sorted(required))}")
    for key in sorted(required - set(body)):
        raise PleError(f"{here}.{key}: missing")
    for key in sorted(set(body) - required - set(optional)):
        raise PleError(f"{here}.{cut(key)}: unknown field "
                       f"(expected some of {', '.join(sorted(required | set(optional)))})")


def _number(x, where: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise PleError(f"{where}: expected a finite number, got {echo(x)}")
    return float(x)


def _stencil(body, here: str) -> Stencil:
    _keys(body, here, {"shape", "cells"})
    shape, cells = body["shape"], body["cells"]
    if (not isinstance(shape, list) or len(shape) not in (3, 4)
            or any(isinstance(s, bool) or not isinstance(s, int) or s < 1 for s in shape)):
        raise PleError(f"{here}.shape: expected 3 (or 4, with a node column) positive integers, got {echo(shape)}")
    size = math.prod(shape)
    if size > MAX_STENCIL_CELLS:
        raise PleError(f"{here}.shape: {size:,} cells (limit {MAX_STENCIL_CELLS:,})")
    if not isinstance(cells, list) or len(cells) != size or any(c not in (0, 1) or isinstance(c, float) for c in cells):
        raise PleError(f"{here}.cells: expected {size} values 0 or 1 (k fastest), got "
                       f"{len(cells) if isinstance(cells, list) else type(cells).__name__}")
    return Stencil(np.array(cells, dtype=bool).reshape(shape))


def _lil(body, here: str, depth: int, loader=None) -> LiL:
    _keys(body, here, {"coarse"}, {"method"})
    method = body.get("method", "auto")
    if method not in ("auto", "elements", "biq"):
        raise PleError(f"{here}.method: expected auto, elements or biq, got {echo(method)}")
    try:
        coarse = lattice_from_dict(body["coarse"], lambda d, w: filter_from_dict(d, w, depth + 1, loader),
                                   _surface_grade)
    except PleError as exc:
        raise PleError(f"{here}.coarse.{exc}") from None
    return LiL(coarse, method)


def _implicit(body, here: str) -> ImplicitFilter:
    kind = body.get("kind") if isinstance(body, dict) else None
    fourier = {"n", "symmetric", "freqs", "coeffs"}
    _keys(body, here, {"kind"}, {"cell", "level", "sheet", "placement"} | (fourier if kind == "fourier" else set()))
    if kind != "fourier" and kind not in TPMS:
        raise PleError(f"{here}.kind: expected one of {', '.join(TPMS)}, fourier; got {echo(kind)}")
    cell = body.get("cell", 1.0)
    if isinstance(cell, list):
        if len(cell) != 3:
            raise PleError(f"{here}.cell: expected a number or three, got {echo(cell)}")
        cell = [_number(c, f"{here}.cell[{n}]") for n, c in enumerate(cell)]
    else:
        cell = _number(cell, f"{here}.cell")
    level = _number(body.get("level", 0.0), f"{here}.level")
    sheet = body.get("sheet", False)
    if not isinstance(sheet, bool):
        raise PleError(f"{here}.sheet: expected true or false")
    placement = similarity_from_dict(body["placement"], f"{here}.placement") if "placement" in body else None
    if placement is not None and not isinstance(placement, Similarity):
        raise PleError(f"{here}.placement: expected a similarity")
    try:
        field = _fourier(body, here, cell, placement) if kind == "fourier" else TPMSField(kind, cell, placement)
        return ImplicitFilter(field, level, VARIANTS[1] if sheet else VARIANTS[0])
    except PleError as exc:
        msg = str(exc)
        raise PleError(msg if msg.startswith(here) else f"{here}: {msg}") from None


def _fourier(body, here: str, cell, placement) -> FourierField:
    for key in ("n", "freqs", "coeffs"):
        if key not in body:
            raise PleError(f"{here}.{key}: missing (a fourier field is given by its coefficients)")
    n = body["n"]
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise PleError(f"{here}.n: expected a positive integer, got {echo(n)}")
    freqs, coeffs = body["freqs"], body["coeffs"]
    if not isinstance(freqs, list) or not isinstance(coeffs, list) or len(freqs) != len(coeffs):
        raise PleError(f"{here}.freqs: expected as many [i, j, k] frequencies as coeffs")
    if len(freqs) > MAX_FOURIER_TERMS:
        raise PleError(f"{here}.freqs: {len(freqs):,} terms (limit {MAX_FOURIER_TERMS:,})")
    for m, f in enumerate(freqs):
        if not isinstance(f, list) or len(f) != 3 or any(isinstance(x, bool) or not isinstance(x, int) for x in f):
            raise PleError(f"{here}.freqs[{m}]: expected 3 integers, got {echo(f)}")
    values = []
    for m, c in enumerate(coeffs):
        if not isinstance(c, list) or len(c) != 2:
            raise PleError(f"{here}.coeffs[{m}]: expected [real, imaginary], got {echo(c)}")
        values.append(complex(_number(c[0], f"{here}.coeffs[{m}][0]"), _number(c[1], f"{here}.coeffs[{m}][1]")))
    symmetric = body.get("symmetric", False)
    if not isinstance(symmetric, bool):
        raise PleError(f"{here}.symmetric: expected true or false")
    return FourierField(np.array(freqs, dtype=np.int64).reshape(-1, 3), np.array(values), n, cell, placement, symmetric)


# ----- bodies (the only file reference of the format) ---------------------------------------------
def _body_to_dict(f: BodyFilter, base) -> dict:
    body = f.body
    if body.source is None:
        raise PleError("filter.body: a body given as arrays cannot be written as data (load it from a mesh file)")
    path = body.source
    if base is not None:
        path = os.path.relpath(os.path.abspath(path), os.path.abspath(base))
    out = {"mesh": Path(path).as_posix(), "mode": f.mode}
    if not body.placement.allclose(Similarity(), 0.0):
        out["placement"] = body.placement.to_dict()
    if body.open != "error":
        out["open"] = body.open
    return out


def _body(body, here: str, loader) -> BodyFilter:
    _keys(body, here, {"mesh"}, {"mode", "placement", "open"})
    path, mode, opened = body["mesh"], body.get("mode", "inside"), body.get("open", "error")
    if not isinstance(path, str) or not path.strip():
        raise PleError(f"{here}.mesh: expected the path of a mesh file, got {echo(path)}")
    if mode not in MODES:
        raise PleError(f"{here}.mode: expected one of {', '.join(MODES)}, got {echo(mode)}")
    if opened not in OPEN_MODES:
        raise PleError(f"{here}.open: expected one of {', '.join(OPEN_MODES)}, got {echo(opened)}")
    placement = similarity_from_dict(body["placement"], f"{here}.placement") if "placement" in body else None
    if placement is not None and not isinstance(placement, Similarity):
        raise PleError(f"{here}.placement: expected a similarity")
    if loader is None:
        raise PleError(f"{here}.mesh: a body mesh is resolved against its JSON file; load the lattice from a file")
    return BodyFilter(loader(path, placement, opened, f"{here}.mesh"), mode)
