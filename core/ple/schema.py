"""The one schema of ``ple-lattice/1`` files, and a strict reader (docs/reliability.md).

``read_json`` turns bytes into data within limits (size, UTF-8, nesting depth, digits of an
integer); ``check_ir`` walks the data against ``SCHEMA`` before anything is built: an unknown
key is rejected with its JSON path and the nearest valid name, every value has its type,
numbers are finite and within range, lists within their sizes. ``ple.ir`` then builds the
lattice from data that is known to be well-formed.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import stat
from pathlib import Path

import numpy as np

from .errors import PleError
from .lattice import MAX_COUNT

MAX_FILE_BYTES = 64 << 20
MAX_DEPTH = 32
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
                "meta": ("json", False)},
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
}
LIST_LIMITS = {"node": MAX_NODES, "beam": MAX_BEAMS, "vec3": 4}


def nearest(name: str, valid) -> str:
    """`` (did you mean 'x'?)`` for the closest valid name, or a list of the valid names."""
    close = difflib.get_close_matches(str(name), list(valid), n=1, cutoff=0.5)
    return f" (did you mean {close[0]!r}?)" if close else f" (expected one of {', '.join(sorted(valid))})"


def _fail(where: str, msg: str):
    raise PleError(f"{where}: {msg}")


def _number(x, where: str, lo: float = -MAX_ABS, hi: float = MAX_ABS) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        _fail(where, f"expected a number, got {_show(x)}")
    v = float(x) if not isinstance(x, int) or abs(x) < 1e300 else math.inf
    if not math.isfinite(v):
        _fail(where, f"must be finite, got {_show(x)}")
    if not lo <= v <= hi:
        _fail(where, f"must lie in [{lo:g}, {hi:g}], got {_show(x)}")
    return v


def _integer(x, where: str, lo: int, hi: int) -> int:
    if isinstance(x, bool) or not isinstance(x, int):
        _fail(where, f"expected an integer, got {_show(x)}")
    if x < lo:
        _fail(where, f"must be at least {lo}, got {_show(x)}")
    if x > hi:
        _fail(where, f"must be at most {hi}, got {_show(x)}")
    return x


def _show(x) -> str:
    text = repr(x)
    return text if len(text) <= 40 else text[:37] + "..."


def _list(x, where: str, n: int | None = None, what: str = "values") -> list:
    if not isinstance(x, list):
        _fail(where, f"expected a list of {what}, got {_show(x)}")
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
            _fail(where, f"expected 'ple-lattice/1', got {_show(x)}")
    elif kind == "number":
        _number(x, where)
    elif kind == "positive":
        if _number(x, where) <= 0:
            _fail(where, f"must be positive, got {_show(x)}")
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
            _fail(where, f"expected true or false, got {_show(x)}")
    elif kind == "ref":
        if isinstance(x, bool) or not isinstance(x, (str, int)):
            _fail(where, f"expected a node id (a name or a position), got {_show(x)}")
        if isinstance(x, int):
            _integer(x, where, 0, MAX_NODES)
        elif len(x) > 200:
            _fail(where, "a node name of more than 200 characters")
    elif kind == "text":
        if not isinstance(x, str) or len(x) > MAX_TEXT:
            _fail(where, f"expected a text of at most {MAX_TEXT:,} characters")
    elif kind == "matrix":
        for r, row in enumerate(_list(x, where, 4, "rows")):
            for c, v in enumerate(_list(row, f"{where}[{r}]", 4, "numbers")):
                _number(v, f"{where}[{r}][{c}]")
    elif kind in ("similarity_kind", "field_kind", "stack_mode"):
        valid = {"similarity_kind": SIMILARITY_KINDS, "field_kind": FIELD_KINDS,
                 "stack_mode": ("raise", "normal")}[kind]
        if not isinstance(x, str) or x not in valid:
            _fail(where, f"unknown kind {_show(x)}{nearest(x, valid) if isinstance(x, str) else ''}")
    elif kind == "json":
        pass  # free-form (meta); depth and size are bounded by read_json
    else:  # pragma: no cover - a schema typo
        raise AssertionError(kind)


def check_object(name: str, x, where: str) -> None:
    """Check ``x`` against ``SCHEMA[name]``: an object, no unknown keys, required keys present,
    every value of its type; and the per-kind keys of similarities and fields."""
    spec = SCHEMA[name]
    if not isinstance(x, dict):
        _fail(where or name, f"expected an object ({name}), got {_show(x)}")
    prefix = f"{where}." if where else ""
    for key in x:
        if key not in spec:
            raise PleError(f"{prefix}{key}: unknown field{nearest(key, spec)}")
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
                raise PleError(f"{prefix}{key}: not a parameter of a {x['kind']} "
                               f"(it takes {', '.join(allowed) or 'none'})")
        for key in allowed:
            if key not in x:
                raise PleError(f"{prefix}{key}: missing for kind {x['kind']!r}")
    if name in ("direction", "transform") and "matrix" in x and "similarity" in x:
        raise PleError(f"{where}: give one of 'matrix' or 'similarity', not both")
    if name == "transform" and "matrix" not in x and "similarity" not in x:
        raise PleError(f"{where}: give one of 'matrix' or 'similarity'")


def check_ir(data) -> None:
    """Validate parsed ``ple-lattice/1`` data against the schema (PleError naming the path)."""
    check_object("lattice", data, "")


def _depth(data, limit: int) -> int:
    """Nesting depth of parsed JSON (iterative; stops once beyond ``limit``)."""
    stack, deepest = [(data, 1)], 0
    while stack:
        x, d = stack.pop()
        if isinstance(x, (list, dict)):
            deepest = max(deepest, d)
            if deepest > limit:
                return deepest
            stack.extend((v, d + 1) for v in (x.values() if isinstance(x, dict) else x))
    return deepest


def check_input_file(path, what: str = "file", max_bytes: int = MAX_FILE_BYTES) -> None:
    """A regular file within ``max_bytes``: clear errors for missing files, folders, FIFOs
    (which would block), devices and size."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise PleError(f"{path}: no such {what}") from None
    except OSError as exc:
        raise PleError(f"{path}: cannot read ({exc.strerror})") from None
    if stat.S_ISDIR(st.st_mode):
        raise PleError(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        raise PleError(f"{path}: is not a regular file (a FIFO, device or socket); give a {what}")
    if st.st_size > max_bytes:
        raise PleError(f"{path}: {st.st_size:,} bytes is larger than the limit {max_bytes:,} for a {what}")


def read_input_file(path, what: str = "file", max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """Bytes of a regular input file (``check_input_file``)."""
    path = Path(path)
    check_input_file(path, what, max_bytes)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise PleError(f"{path}: cannot read ({exc.strerror})") from None


def read_json(path, what: str = "JSON file", max_depth: int = MAX_DEPTH):
    """Parse a JSON file within limits: size, strict UTF-8, nesting depth, integer digits."""
    raw = read_input_file(path, what)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise PleError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    try:
        data = json.loads(text)  # NaN/Infinity parse; the schema names their field
    except json.JSONDecodeError as exc:
        raise PleError(f"{path}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except RecursionError:
        raise PleError(f"{path}: JSON nested deeper than {max_depth} levels") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise PleError(f"{path}: unreadable JSON ({str(exc).splitlines()[0][:120]})") from None
    if _depth(data, max_depth) > max_depth:
        raise PleError(f"{path}: JSON nested deeper than {max_depth} levels")
    return data


MAX_NPY_BYTES = 1 << 30


def load_npy(path: str, flag: str) -> np.ndarray:
    """A ``.npy`` array given as input: a regular file of at most 1 GiB holding one array (not
    an ``.npz`` archive, no pickles); the header is checked before the data is read."""
    check_input_file(path, f"{flag} .npy file", MAX_NPY_BYTES)
    try:
        with open(path, "rb") as fh:
            version = np.lib.format.read_magic(fh)
            shape, _, dtype = np.lib.format._read_array_header(fh, version, max_header_size=10_000)
            if dtype.hasobject or math.prod(shape) * dtype.itemsize > MAX_NPY_BYTES:
                raise ValueError(f"array {shape} of {dtype} is not a plain numeric array within 1 GiB")
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, TypeError) as exc:
        raise PleError(f"{flag} {path}: cannot read a .npy array ({str(exc).splitlines()[0][:160]})") from None
    if not isinstance(arr, np.ndarray):
        raise PleError(f"{flag} {path}: expected a .npy array, got an archive")
    return arr


__all__ = ["MAX_DEPTH", "SCHEMA", "check_input_file", "check_ir", "check_object", "load_npy", "nearest",
           "read_input_file", "read_json"]
