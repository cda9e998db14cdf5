"""Records spilled to disk by key, for computations done block by block in bounded memory
(``ple.meshing.selfcheck.check_triangles``): one append-only file per key in a temporary
directory, removed when read back or on close."""

from __future__ import annotations

import os
import tempfile

import numpy as np


class SpillFiles:
    """``put(key, records)`` appends structured records to the key's file; ``take(key)`` reads
    them back (and removes the file); ``keys()`` lists the keys put. A context manager: the
    directory (in ``dir``, default the system's temporary directory) goes on exit."""

    def __init__(self, dir=None):
        self._dir = tempfile.TemporaryDirectory(prefix="ple-spill-", dir=dir)
        self._dtypes: dict = {}

    def _path(self, key: int) -> str:
        return os.path.join(self._dir.name, f"{int(key)}.bin")

    def put(self, key: int, records: np.ndarray) -> None:
        if self._dtypes.setdefault(key, records.dtype) != records.dtype:
            raise ValueError(f"spill key {key}: records of another dtype")
        with open(self._path(key), "ab") as fh:
            np.ascontiguousarray(records).tofile(fh)

    def keys(self) -> list[int]:
        return sorted(self._dtypes)

    def take(self, key: int) -> np.ndarray:
        path = self._path(key)
        out = np.fromfile(path, self._dtypes.pop(key))
        os.remove(path)
        return out

    def close(self) -> None:
        self._dir.cleanup()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()
