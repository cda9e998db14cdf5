"""Geometric series in closed form: sums of the powers of a similarity's scale factor along a steady
row (thesis §3.6 integral properties, §4.4.5 Eq. 4.13 BeCOTS patterns, mean radii)."""

from __future__ import annotations

import numpy as np

UNIT_RATIO = 1e-15  # |q - 1| below this: every term equals the first (the sum is n terms)


def geometric_sum(q: float, n: int, first: float = 1.0) -> float:
    """``first · Σ_{i=0}^{n-1} q^i`` in closed form; ``q == 1`` is the named special case ``n · first``."""
    if abs(q - 1.0) <= UNIT_RATIO:
        return float(n) * first
    return first * (1.0 - q ** n) / (1.0 - q)


def operator_geometric_sum(op, n: int):
    """``Σ_{i=0}^{n-1} op^i`` for a square matrix ``op`` (a linear map, e.g. a similarity acting on
    moment matrices, §3.6 extended to moments), by doubling: O(log n) products, no inverse, so
    eigenvalues equal to 1 (translations, unit factors) need no special case."""
    op = np.asarray(op, dtype=float)
    eye = np.eye(len(op))
    power, total = eye, np.zeros_like(op)  # op^m and Σ_{i<m} op^i for the prefix m of n's bits
    for bit in bin(int(n))[2:]:
        total, power = total + power @ total, power @ power  # m -> 2m
        if bit == "1":
            total, power = total + power, power @ op  # m -> m + 1
    return total
