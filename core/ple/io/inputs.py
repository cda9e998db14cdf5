"""Input files read within limits (docs/reliability.md): regular files only (a FIFO would block,
a device never ends), a size limit, strict UTF-8, JSON nesting depth and integer digits, and
``.npy`` arrays whose header is checked before the data is read (no pickles, no archives)."""

from __future__ import annotations

import json
import math
import os
import stat
from pathlib import Path

import numpy as np

from ..errors import PleError

MAX_FILE_BYTES = 64 << 20
MAX_DEPTH = 32


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
        raise PleError(f"{path}: no such file (expected a {what})") from None
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
            if dtype.hasobject or dtype.kind == "c" or math.prod(shape) * dtype.itemsize > MAX_NPY_BYTES:
                raise ValueError(f"array {shape} of {dtype} is not a plain numeric array within 1 GiB")
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError, TypeError) as exc:
        raise PleError(f"{flag} {path}: cannot read a .npy array ({str(exc).splitlines()[0][:160]})") from None
    if not isinstance(arr, np.ndarray):
        raise PleError(f"{flag} {path}: expected a .npy array, got an archive")
    return arr


__all__ = ["MAX_DEPTH", "MAX_FILE_BYTES", "MAX_NPY_BYTES", "check_input_file", "load_npy", "read_input_file",
           "read_json"]
