"""Geometric series in closed form: sums of the powers of a similarity's scale factor along a steady
row (thesis §3.6 integral properties, §4.4.5 Eq. 4.13 BeCOTS patterns, mean radii)."""

from __future__ import annotations

UNIT_RATIO = 1e-15  # |q - 1| below this: every term equals the first (the sum is n terms)


def geometric_sum(q: float, n: int, first: float = 1.0) -> float:
    """``first · Σ_{i=0}^{n-1} q^i`` in closed form; ``q == 1`` is the named special case ``n · first``."""
    if abs(q - 1.0) <= UNIT_RATIO:
        return float(n) * first
    return first * (1.0 - q ** n) / (1.0 - q)
