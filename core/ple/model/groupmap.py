"""Node-group maps: lattices whose groups are placed by maps that are not similarities.

A steady lattice places node-group (i, j, k) by the similarity ``G ∘ W**k ∘ V**j ∘ U**i``
(``Lattice.group_matrices``). A *group map* replaces that similarity by any map that takes
balls to balls: Möbius steady patterns (thesis §11.3), TMI maps (§11.4), rectified warps
(§3.3–3.4). A lattice holding one (``Lattice.set_group_map``) evaluates its nodes through
``map_balls``; everything built on evaluation (``ple eval``, bounds, the naive queries) works
unchanged, and what needs per-group similarities (hub templates, closed-form measures) takes
the general per-hub path on ``Lattice.explicit`` (one group, every node its own template).
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class GroupMap(ABC):
    """Places the template balls of node-group (i, j, k); subclasses say how."""

    kind = "group map"

    @abstractmethod
    def map_balls(self, i: np.ndarray, j: np.ndarray, k: np.ndarray, centers: np.ndarray,
                  radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Images of template balls (centres (N, 3), radii (N,)) in groups (i[n], j[n], k[n])."""

    @abstractmethod
    def describe(self) -> dict:
        """A JSON-ready description (``ple info``)."""
