"""PLE — the Programmed Lattice Editor core: lattice programs, similarities, lazy evaluation,
queries, filters and tessellation, with no Blender dependency.

The package is a stack of layers (docs/architecture.md). This top level exports what a program
or a script needs: the program API (the names a program has in scope) and the ways to get a
lattice from a program, an IR file or a preset. Everything else is imported from its layer,
e.g. ``from ple.queries import biq`` or ``from ple.meshing.tessellate import tessellate``.
"""

from .algebra.mobius import Cline, Mobius
from .algebra.similarity import Identity, Rotation, Scaling, Screw, Similarity, Swirl, Translation
from .algebra.vectors import Pt, Vec
from .clg.field import FieldSolid
from .clg.model import CLG
from .errors import PleError
from .filters import FilteredLattice, FourierField, ImplicitFilter, LiL, Stencil, TPMSField, lil
from .io.irfile import load_ir, save_ir
from .model.becots import BeCOTSField
from .model.becots_builders import becots_lattice, set_field, stack_lattice
from .model.lattice import BeamPattern, Direction, Evaluation, Lattice, Node, Region
from .model.mobius import TMIMap, mobius_frames_lattice, mobius_lattice, with_control_frames
from .model.planar import ShapeOntoCone, SteadyMap2, snap_corner
from .model.warp import RectifiedWarp, rectified_warp
from .program.clg_sources import load_clg
from .program.runtime import Range, compile_program
from .program.sources import load_lattice

__version__ = "0.1.0"

__all__ = [
    "CLG", "BeCOTSField", "BeamPattern", "Cline", "Direction", "Evaluation", "FieldSolid", "FilteredLattice",
    "FourierField",
    "Identity", "ImplicitFilter", "Lattice", "LiL", "Mobius", "Node", "PleError", "Pt", "Range", "RectifiedWarp",
    "Region", "Rotation", "Scaling", "Screw", "ShapeOntoCone", "Similarity", "Stencil", "SteadyMap2", "Swirl",
    "TMIMap", "TPMSField", "Translation", "Vec", "becots_lattice", "compile_program", "lil", "load_clg", "load_ir",
    "load_lattice", "mobius_frames_lattice", "mobius_lattice", "rectified_warp", "save_ir", "set_field",
    "with_control_frames",
    "snap_corner", "stack_lattice",
]
