"""The data-only CLG description, format ``ple-clg/1`` (docs/formats.md): dicts to CLGs and back.

Loading never runs code. Every validation error names the offending field by its JSON path,
e.g. ``chunks.shell.difference[1].beam.scale[0]: must be > 0``.
"""

from __future__ import annotations

import math

from ..errors import PleError, cut, echo
from ..model.ir import lattice_from_dict, lattice_to_dict
from .field import FieldSolid, field_from_dict, field_to_dict
from .model import (
    CLG,
    MAX_DEPTH,
    OPS,
    ChunkRef,
    Compound,
    Material,
    Op,
    Prim,
    scale_pair,
    scale_value,
)

FORMAT = "ple-clg/1"
TOP_KEYS = {"format", "pattern", "chunks", "solid", "materials", "description"}
PRIM_KEYS = {"ball": {"node", "scale", "material"}, "beam": {"from", "to", "scale", "material"},
             "hollow_beam": {"from", "to", "scale", "hollow", "material"},
             "extended_hub": {"node", "scale", "material"},
             "connector": {"node", "outer", "inner", "reach", "material"}}


def clg_from_dict(data, where: str = "", depth: int = 1) -> CLG:
    """Build a CLG from parsed ``ple-clg/1`` data; ``where`` prefixes field paths (nesting)."""
    pre = f"{where}." if where else ""
    if depth > MAX_DEPTH:
        raise PleError(f"{where}: nesting deeper than {MAX_DEPTH} levels")
    if not isinstance(data, dict):
        raise PleError(f"{where or 'clg file'}: expected a JSON object")
    if data.get("format") != FORMAT:
        raise PleError(f"{pre}format: expected {echo(FORMAT)}, got {echo(data.get('format'))}")
    unknown = sorted(set(data) - TOP_KEYS)
    if unknown:
        raise PleError(f"{pre}{cut(unknown[0])}: unknown field (expected some of {', '.join(sorted(TOP_KEYS))})")
    for key in ("pattern", "chunks", "solid"):
        if key not in data:
            raise PleError(f"{pre}{key}: missing")
    try:
        pattern = lattice_from_dict(data["pattern"])
    except PleError as exc:
        raise PleError(f"{pre}pattern.{exc}") from None
    mats_in = data.get("materials", {})
    if not isinstance(mats_in, dict):
        raise PleError(f"{pre}materials: expected an object {{ID: {{replace, frame}}}}")
    materials = {}
    for mid, m in mats_in.items():
        w = f"{pre}materials.{mid}"
        if not isinstance(m, dict):
            raise PleError(f"{w}: expected an object with replace and frame")
        bad = sorted(set(m) - {"replace", "frame", "color"})
        if bad:
            raise PleError(f"{w}.{cut(bad[0])}: unknown field")
        frame = m.get("frame", "world")
        if frame not in ("world", "beam"):
            raise PleError(f"{w}.frame: expected 'world' or 'beam', got {echo(frame)}")
        rep = m.get("replace")
        if isinstance(rep, dict) and "fourier" in rep:  # a fitted field, inline (ple.clg.field)
            if len(rep) != 1:
                raise PleError(f"{w}.replace: a field is {{\"fourier\": {{...}}}} alone")
            rep = field_from_dict(rep["fourier"], f"{w}.replace.fourier")
        elif rep is not None:
            rep = clg_from_dict(rep, f"{w}.replace", depth + 1)
        materials[str(mid)] = Material(rep, frame)
    chunks_in = data["chunks"]
    if not isinstance(chunks_in, dict) or not chunks_in:
        raise PleError(f"{pre}chunks: expected an object of named chunk expressions")
    chunks = {str(name): _expr(e, f"{pre}chunks.{name}", set(materials)) for name, e in chunks_in.items()}
    solid = _solid(data["solid"], f"{pre}solid", set(chunks))
    try:
        return CLG(pattern, chunks, solid, materials, str(data.get("description", "")))
    except PleError as exc:
        msg = str(exc)
        raise PleError(msg if msg.startswith(pre) and pre else f"{pre}{msg}") from None


def _one_key(e, where: str) -> tuple[str, object]:
    if not isinstance(e, dict) or len(e) != 1:
        raise PleError(f"{where}: expected an object with one key (a primitive or an operator), got {echo(e)}")
    return next(iter(e.items()))


def _node(x, where: str):
    if isinstance(x, list) and len(x) == 4:
        for v, name in zip(x[:3], ("di", "dj", "dk")):
            if isinstance(v, bool) or not isinstance(v, int):
                raise PleError(f"{where}: {name} must be an integer, got {echo(v)}")
        if isinstance(x[3], bool) or not isinstance(x[3], (int, str)):
            raise PleError(f"{where}: unknown node {echo(x[3])}")
        return tuple(x)
    raise PleError(f"{where}: expected [di, dj, dk, n], got {echo(x)}")


def _num_field(d: dict, key: str, where: str) -> float:
    if key not in d:
        raise PleError(f"{where}.{key}: missing")
    return scale_value(d[key], f"{where}.{key}")


def _expr(e, where: str, materials: set):
    key, val = _one_key(e, where)
    w = f"{where}.{key}"
    if key in OPS:
        if not isinstance(val, list) or not val:
            raise PleError(f"{w}: expected a non-empty list of expressions")
        return Op(key, tuple(_expr(x, f"{w}[{n}]", materials) for n, x in enumerate(val)))
    if key not in PRIM_KEYS:
        raise PleError(f"{w}: unknown operator or primitive (expected one of "
                       f"{', '.join(OPS + tuple(PRIM_KEYS))})")
    if not isinstance(val, dict):
        raise PleError(f"{w}: expected an object")
    bad = sorted(set(val) - PRIM_KEYS[key])
    if bad:
        raise PleError(f"{w}.{cut(bad[0])}: unknown field")
    mat = val.get("material")
    if mat is not None:
        if str(mat) not in materials:
            raise PleError(f"{w}.material: unknown material {echo(mat)}")
        mat = str(mat)
    for k in PRIM_KEYS[key] - {"material", "scale"}:
        if k not in val:
            raise PleError(f"{w}.{k}: missing")
    if key == "ball":
        s = scale_value(val.get("scale", 1.0), f"{w}.scale")
        return Prim(_node(val["node"], f"{w}.node"), s, None, 0.0, mat)
    if key == "extended_hub":
        s1, s2 = scale_pair(val.get("scale", [1.0, 1.0]), f"{w}.scale")
        return Compound(key, (_node(val["node"], f"{w}.node"), s1, s2), mat)
    if key == "connector":
        s1, s2 = _num_field(val, "outer", w), _num_field(val, "inner", w)
        if s2 >= s1:
            raise PleError(f"{w}.inner: must be smaller than outer ({s1}), got {s2}")
        return Compound(key, (_node(val["node"], f"{w}.node"), s1, s2, _num_field(val, "reach", w)), mat)
    a, b = _node(val["from"], f"{w}.from"), _node(val["to"], f"{w}.to")
    s1, s2 = scale_pair(val.get("scale", [1.0, 1.0]), f"{w}.scale")
    if key == "beam":
        return Prim(a, s1, b, s2, mat)
    h = val["hollow"]
    if isinstance(h, bool) or not isinstance(h, (int, float)) or not math.isfinite(h) or not 0 < h < 1:
        raise PleError(f"{w}.hollow: must be in (0, 1), got {echo(h)}")
    return Compound(key, (a, b, s1, s2, float(h)), mat)


def _solid(e, where: str, names: set):
    if isinstance(e, str):
        if e not in names:
            raise PleError(f"{where}: unknown chunk {echo(e)} (chunks: {', '.join(sorted(names))})")
        return ChunkRef(e)
    key, val = _one_key(e, where)
    if key == "chunk":
        return _solid(val, f"{where}.chunk", names)
    if key not in OPS:
        raise PleError(f"{where}.{cut(key)}: unknown operator (expected {', '.join(OPS)} over chunk names)")
    if not isinstance(val, list) or not val:
        raise PleError(f"{where}.{key}: expected a non-empty list")
    return Op(key, tuple(_solid(x, f"{where}.{key}[{n}]", names) for n, x in enumerate(val)))


# ----- back to data -------------------------------------------------------------------------------------
def _ref_out(r) -> list:
    return [r.di, r.dj, r.dk, r.n]


def expr_to_dict(e) -> dict | str:
    if isinstance(e, ChunkRef):
        return e.name
    if isinstance(e, Op):
        return {e.kind: [expr_to_dict(x) for x in e.args]}
    out: dict = ({"ball": {"node": _ref_out(e.a), "scale": e.sa}} if e.b is None else
                 {"beam": {"from": _ref_out(e.a), "to": _ref_out(e.b), "scale": [e.sa, e.sb]}})
    if e.material is not None:
        next(iter(out.values()))["material"] = e.material
    return out


def clg_to_dict(clg: CLG) -> dict:
    """The ``ple-clg/1`` data of a CLG, compound primitives expanded (data-only materials only)."""
    mats = {}
    for mid, m in clg.materials.items():
        if m.replace is not None and not isinstance(m.replace, (CLG, FieldSolid)):
            raise PleError(f"materials.{mid}: a material given by a function cannot be written as data")
        rep = m.replace
        mats[mid] = {"frame": m.frame, "replace": None if rep is None else
                     field_to_dict(rep) if isinstance(rep, FieldSolid) else clg_to_dict(rep)}
    out = {"format": FORMAT, "pattern": lattice_to_dict(clg.pattern, resolved=False),
           "chunks": {k: expr_to_dict(v) for k, v in clg.chunks.items()}, "solid": expr_to_dict(clg.solid),
           "materials": mats}
    if clg.description:
        out["description"] = clg.description
    return out
