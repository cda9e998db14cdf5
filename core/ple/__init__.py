"""PLE — the Programmed Lattice Editor core: lattice programs, similarities, lazy evaluation,
queries, filters and tessellation, with no Blender dependency."""

from .errors import PleError
from .geometry import Pt, Vec
from .lattice import BeamPattern, Direction, Evaluation, Lattice, Node, Region
from .program import Range, compile_program, load_lattice
from .similarity import Identity, Rotation, Scaling, Screw, Similarity, Swirl, Translation

__version__ = "0.1.0"

__all__ = [
    "BeamPattern", "Direction", "Evaluation", "Identity", "Lattice", "Node", "PleError", "Pt", "Range",
    "Region", "Rotation", "Scaling", "Screw", "Similarity", "Swirl", "Translation", "Vec",
    "compile_program", "load_lattice",
]
