"""The one schema of ``ple-lattice/1`` data (docs/reliability.md).

``check_ir`` walks parsed data against ``SCHEMA`` before anything is built: an unknown key is
rejected with its JSON path and the nearest valid name, every value has its type, numbers are
finite and within range, lists within their sizes. ``ple.model.ir`` then builds the lattice
from data that is known to be well-formed. The top-level ``"grade"`` is left to
``ple.model.grading.grade_from_dict`` and the ``"filter"`` to
``ple.filters.ir`` (filters live above the model). Reading files within limits (size, UTF-8,
nesting depth) is ``ple.io.inputs``.
"""

from __future__ import annotations

import difflib
import math

from ..errors import PleError, cut, echo
from .lattice import MAX_COUNT

MAX_NODES = 100_000
MAX_BEAMS = 1_000_000
MAX_TEXT = 100_000
MAX_ABS = 1e100  # coordinates and similarity parameters: cubes (volumes) stay finite
SIMILARITY_KINDS = {
    "identity": (), "translation": ("vector",), "rotation": ("angle", "axis", "point"),
    "scaling": ("factor", "point"), "swirl": ("angle", "axis", "point", "factor"),
    "screw": ("angle", "axis", "point", "distance"),
}
FIELD_KINDS = {"translation": ("a", "tu", "tv"), "cone": ("a", "apex", "axis", "u", "v"),
               "cylinder": ("a", "apex", "axis", "u", "v")}  # ple.becots.KINDS

# object name -> {key: (type, required)}; a type is a name handled by _check_value or "@object".
SCHEMA: dict[str, dict[str, tuple[str, bool]]] = {
    "lattice": {"format": ("format", True), "nodes": ("[node]", True), "beams": ("[beam]", False),
                "U": ("@direction", False), "V": ("@direction", False), "W": ("@direction", False),
                "placement": ("@transform", False), "becots": ("@becots", False), "description": ("text", False),
                "meta": ("json", False), "filter": ("filter", False),
                "grade": ("grade", False), "mobius": ("@mobius", False)},
    "node": {"id": ("ref", False), "center": ("vec3", True), "radius": ("positive", True)},
    "beam": {"from": ("ref", True), "to": ("ref", True), "offset": ("offset", False)},
    "direction": {"count": ("count", False), "cumulative": ("bool", False), "matrix": ("matrix", False),
                  "similarity": ("@similarity", False)},
    "transform": {"matrix": ("matrix", False), "similarity": ("@similarity", False)},
    "similarity": {"kind": ("similarity_kind", True), "vector": ("vec3", False), "angle": ("number", False),
                   "axis": ("vec3", False), "point": ("vec3", False), "factor": ("positive", False),
                   "distance": ("number", False)},
    "becots": {"corners": ("[vec3]", False), "field": ("@field", False), "counts": ("count2", True),
               "branch": ("int2", False), "closed": ("bool", False), "stack": ("@stack", False)},
    "field": {"kind": ("field_kind", True), "a": ("vec3", False), "tu": ("vec3", False), "tv": ("vec3", False),
              "apex": ("vec3", False), "axis": ("vec3", False), "u": ("number2", False), "v": ("number2", False)},
    "stack": {"layers": ("count", True), "nodes_per_layer": ("count", True), "step": ("vec3", True),
              "mode": ("stack_mode", False)},
    # Möbius steady patterns (thesis §11.3): complex 2x2 matrices, each entry [re, im]
    "mobius": {"U": ("@mobius_direction", False), "V": ("@mobius_direction", False),
               "W": ("@mobius_direction", False), "frame": ("@mobius_frame", False)},
    "mobius_direction": {"count": ("count", False), "matrix": ("complex_matrix", True),
                         "split": ("@mobius_split", False)},
    "mobius_frame": {"matrix": ("complex_matrix", True)},
    "mobius_split": {"similarity": ("@canonical", True), "inversion": ("complex_matrix", True)},
    "canonical": {"factor": ("positive", True), "angle": ("number", True), "axis": ("vec3", True),
                  "point": ("vec3", True), "distance": ("number", True)},
}
LIST_LIMITS = {"node": MAX_NODES, "beam": MAX_BEAMS, "vec3": 4}


def nearest(name: str, valid) -> str:
    """`` (did you mean 'x'?)`` for the closest valid name, or a list of the valid names."""
    close = difflib.get_close_matches(cut(name), list(valid), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else f" (expected one of {', '.join(sorted(valid))})"


def _fail(where: str, msg: str):
    raise PleError(f"{where}: {msg}")


def _number(x, where: str, lo: float = -MAX_ABS, hi: float = MAX_ABS) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        _fail(where, f"expected a number, got {echo(x)}")
    v = float(x) if not isinstance(x, int) or abs(x) < 1e300 else math.inf
    if not math.isfinite(v):
        _fail(where, f"must be finite, got {echo(x)}")
    if not lo <= v <= hi:
        _fail(where, f"must lie in [{lo:g}, {hi:g}], got {echo(x)}")
    return v


def _integer(x, where: str, lo: int, hi: int) -> int:
    if isinstance(x, bool) or not isinstance(x, int):
        _fail(where, f"expected an integer, got {echo(x)}")
    if x < lo:
        _fail(where, f"must be at least {lo}, got {echo(x)}")
    if x > hi:
        _fail(where, f"must be at most {hi}, got {echo(x)}")
    return x


def _list(x, where: str, n: int | None = None, what: str = "values") -> list:
    if not isinstance(x, list):
        _fail(where, f"expected a list of {what}, got {echo(x)}")
    if n is not None and len(x) != n:
        _fail(where, f"expected {n} {what}, got {len(x)}")
    return x


def _check_value(kind: str, x, where: str) -> None:
    if kind.startswith("@"):
        check_object(kind[1:], x, where)
    elif kind.startswith("["):
        item = kind[1:-1]
        _list(x, where, what=f"{item}s")
        limit = LIST_LIMITS.get(item, MAX_NODES)
        if len(x) > limit:
            _fail(where, f"{len(x):,} entries is more than the limit {limit:,}")
        for n, v in enumerate(x):
            _check_value("@" + item if item in SCHEMA else item, v, f"{where}[{n}]")
    elif kind == "format":
        if x != "ple-lattice/1":
            _fail(where, f"expected 'ple-lattice/1', got {echo(x)}")
    elif kind == "number":
        _number(x, where)
    elif kind == "positive":
        if _number(x, where) <= 0:
            _fail(where, f"must be positive, got {echo(x)}")
    elif kind == "vec3":
        for n, c in enumerate(_list(x, where, 3, "numbers")):
            _number(c, f"{where}[{n}]")
    elif kind in ("number2", "int2", "count2"):
        for n, c in enumerate(_list(x, where, 2, "numbers" if kind == "number2" else "integers")):
            if kind == "number2":
                _number(c, f"{where}[{n}]")
            else:
                _integer(c, f"{where}[{n}]", 1 if kind == "count2" else -1000, MAX_COUNT if kind == "count2" else 1000)
    elif kind == "offset":
        for n, c in enumerate(_list(x, where, 3, "integers")):
            _integer(c, f"{where}[{n}]", -MAX_COUNT, MAX_COUNT)
    elif kind == "count":
        _integer(x, where, 1, MAX_COUNT)
    elif kind == "bool":
        if not isinstance(x, bool):
            _fail(where, f"expected true or false, got {echo(x)}")
    elif kind == "ref":
        if isinstance(x, bool) or not isinstance(x, (str, int)):
            _fail(where, f"expected a node id (a name or a position), got {echo(x)}")
        if isinstance(x, int):
            _integer(x, where, 0, MAX_NODES)
        elif len(x) > 200:
            _fail(where, "a node name of more than 200 characters")
    elif kind == "text":
        if not isinstance(x, str) or len(x) > MAX_TEXT:
            _fail(where, f"expected a text of at most {MAX_TEXT:,} characters")
    elif kind == "complex_matrix":
        for r, row in enumerate(_list(x, where, 2, "rows")):
            for c, v in enumerate(_list(row, f"{where}[{r}]", 2, "complex numbers [re, im]")):
                for n, part in enumerate(_list(v, f"{where}[{r}][{c}]", 2, "numbers [re, im]")):
                    _number(part, f"{where}[{r}][{c}][{n}]")
    elif kind == "matrix":
        for r, row in enumerate(_list(x, where, 4, "rows")):
            for c, v in enumerate(_list(row, f"{where}[{r}]", 4, "numbers")):
                _number(v, f"{where}[{r}][{c}]")
    elif kind in ("similarity_kind", "field_kind", "stack_mode"):
        valid = {"similarity_kind": SIMILARITY_KINDS, "field_kind": FIELD_KINDS,
                 "stack_mode": ("raise", "normal")}[kind]
        if not isinstance(x, str) or x not in valid:
            _fail(where, f"unknown kind {echo(x)}{nearest(x, valid) if isinstance(x, str) else ''}")
    elif kind == "json":
        pass  # free-form (meta); depth and size are bounded by ple.io.inputs.read_json
    elif kind == "filter":
        pass  # validated, with its own paths and names, by ple.filters.ir.filter_from_dict
    elif kind == "grade":
        pass  # validated, with its own paths and names, by ple.model.grading.grade_from_dict
    else:  # pragma: no cover - a schema typo
        raise AssertionError(kind)


def check_object(name: str, x, where: str) -> None:
    """Check ``x`` against ``SCHEMA[name]``: an object, no unknown keys, required keys present,
    every value of its type; and the per-kind keys of similarities and fields."""
    spec = SCHEMA[name]
    if not isinstance(x, dict):
        _fail(where or name, f"expected an object ({name}), got {echo(x)}")
    prefix = f"{where}." if where else ""
    for key in x:
        if key not in spec:
            raise PleError(f"{prefix}{cut(key)}: unknown field{nearest(key, spec)}")
    for key, (kind, required) in spec.items():
        if key not in x:
            if required:
                raise PleError(f"{prefix}{key}: missing")
            continue
        _check_value(kind, x[key], f"{prefix}{key}")
    if name in ("similarity", "field"):
        allowed = (SIMILARITY_KINDS if name == "similarity" else FIELD_KINDS)[x["kind"]]
        for key in x:
            if key != "kind" and key not in allowed:
                raise PleError(f"{prefix}{cut(key)}: not a parameter of a {x['kind']} "
                               f"(it takes {', '.join(allowed) or 'none'})")
        for key in allowed:
            if key not in x:
                raise PleError(f"{prefix}{key}: missing for kind {echo(x['kind'])}")
    if name in ("direction", "transform") and "matrix" in x and "similarity" in x:
        raise PleError(f"{where}: give one of 'matrix' or 'similarity', not both")
    if name == "transform" and "matrix" not in x and "similarity" not in x:
        raise PleError(f"{where}: give one of 'matrix' or 'similarity'")


def check_ir(data) -> None:
    """Validate parsed ``ple-lattice/1`` data against the schema (PleError naming the path)."""
    check_object("lattice", data, "")


__all__ = ["LIST_LIMITS", "MAX_ABS", "MAX_BEAMS", "MAX_NODES", "MAX_TEXT", "SCHEMA", "check_ir", "check_object",
           "nearest"]
