"""Index stencils (thesis §9: F(N) = S[i mod x, j mod y, k mod z]): Boolean arrays over a
period box of node-groups, and the common named hierarchical patterns."""

from __future__ import annotations

import numpy as np

from ..errors import PleError, echo
from .base import Filter

MAX_STENCIL_CELLS = 10**8  # a named stencil's period box (a Boolean array of this size)
STENCIL_NAMES = ("corners", "edges", "faces", "checker", "layers")


class Stencil(Filter):
    """Boolean stencil S of shape (x, y, z), or (x, y, z, nn) to decide per node id as well."""

    def __init__(self, array) -> None:
        s = np.asarray(array)
        if s.dtype != bool:
            if not np.issubdtype(s.dtype, np.number) or not np.isin(s, (0, 1)).all():
                raise PleError("stencil must be a Boolean (or 0/1) array")
            s = s.astype(bool)
        if s.ndim not in (3, 4) or min(s.shape) < 1:
            raise PleError(f"stencil must have shape (x, y, z) or (x, y, z, nodes), got {s.shape}")
        self.array = s

    def node_mask(self, lat, node_index, center, radius):
        s = self.array
        idx = np.asarray(node_index, dtype=np.int64)
        key = (idx[:, 0] % s.shape[0], idx[:, 1] % s.shape[1], idx[:, 2] % s.shape[2])
        if s.ndim == 4:
            if s.shape[3] != len(lat.nodes):
                raise PleError(f"stencil has {s.shape[3]} node columns but the lattice has {len(lat.nodes)} nodes")
            key = key + (idx[:, 3],)
        return s[key]

    @staticmethod
    def named(name: str, period=4, width: int = 1) -> Stencil:
        """Common hierarchical patterns over a period box (x, y, z):
        ``corners`` keeps groups with all three indices ≡ 0 (isolated clusters), ``edges`` those
        with at least two ≡ 0 (a coarse cubic frame whose beams are made of fine beams),
        ``faces`` those with at least one ≡ 0 (coarse cell walls), ``checker`` alternate blocks
        of a 2x2x2 checkerboard, ``layers`` the first ``width`` k-layers of every period."""
        per = (period,) * 3 if np.isscalar(period) else tuple(period)
        if len(per) != 3 or any(int(p) != p or p < 1 for p in per):
            raise PleError(f"stencil period must be a positive integer or three of them, got {echo(period)}")
        if int(width) != width or width < 1:
            raise PleError(f"stencil width must be a positive integer, got {echo(width)}")
        x, y, z = (int(p) for p in per)
        if x * y * z > MAX_STENCIL_CELLS:
            raise PleError(f"stencil period {x}x{y}x{z} has more than {MAX_STENCIL_CELLS:,} cells")
        i, j, k = np.meshgrid(np.arange(x), np.arange(y), np.arange(z), indexing="ij")
        on = [(i % x) < width, (j % y) < width, (k % z) < width]
        hits = on[0].astype(int) + on[1] + on[2]
        if name == "corners":
            s = hits == 3
        elif name == "edges":
            s = hits >= 2
        elif name == "faces":
            s = hits >= 1
        elif name == "checker":
            s = ((2 * i // x) + (2 * j // y) + (2 * k // z)) % 2 == 0
        elif name == "layers":
            s = on[2]
        else:
            raise PleError(f"unknown stencil {echo(name)}; named stencils: {', '.join(STENCIL_NAMES)}")
        return Stencil(s)
