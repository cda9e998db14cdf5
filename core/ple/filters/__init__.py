"""Layer 4 — hierarchical lattices (thesis §9): the filter model and filtered evaluation, index
stencils, Lattice-in-Lattice, implicit (TPMS and symmetric Fourier) fields."""

from .base import Filter, FilteredLattice, all_of
from .implicit import FourierField, ImplicitFilter, TPMSField
from .lil import LiL, lil
from .stencil import Stencil

__all__ = ["Filter", "FilteredLattice", "FourierField", "ImplicitFilter", "LiL", "Stencil", "TPMSField",
           "all_of", "lil"]
