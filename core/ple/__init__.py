"""PLE — the Programmed Lattice Editor core: lattice programs, similarities, lazy evaluation,
queries, filters and tessellation, with no Blender dependency."""

from .algebra.similarity import Identity, Rotation, Scaling, Screw, Similarity, Swirl, Translation
from .algebra.vectors import Pt, Vec
from .errors import PleError
from .model.lattice import BeamPattern, Direction, Evaluation, Lattice, Node, Region
from .program.runtime import Range, compile_program
from .program.sources import load_lattice

__version__ = "0.1.0"

__all__ = [
    "BeamPattern", "Direction", "Evaluation", "Identity", "Lattice", "Node", "PleError", "Pt", "Range",
    "Region", "Rotation", "Scaling", "Screw", "Similarity", "Swirl", "Translation", "Vec",
    "compile_program", "load_lattice",
]
