"""RangeFinder (thesis §7.1–7.3): placeholder delegating to the naive path until the
accelerated path lands."""

from __future__ import annotations

import numpy as np

from .lattice import Lattice


def lattice_hits(lat: Lattice, c: np.ndarray, r: np.ndarray):
    from .biq import _naive_hits

    nh, bh = _naive_hits(lat, c, r)
    return nh, bh, "naive"


def lattice_any(lat: Lattice, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    from .biq import naive_any

    return naive_any(lat, c, r)
