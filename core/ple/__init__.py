"""PLE — the Programmed Lattice Editor core: lattice programs, similarities, lazy evaluation,
queries, filters and tessellation, with no Blender dependency.

The package is a stack of layers (docs/architecture.md). This top level exports what a program
or a script needs: the program API (the names a program has in scope) and the ways to get a
lattice from a program, an IR file or a preset. Everything else is imported from its layer,
e.g. ``from ple.queries import biq`` or ``from ple.meshing.tessellate import tessellate``.
"""

import importlib

# name -> module (relative to ple): imported on first use (PEP 562), so `import ple` and the CLI's
# start-up pay only for what they use (issue 14: `ple presets` starts in under 0.3 s)
_EXPORTS = {
    "BeCOTSField": ".model.becots",
    "BeamPattern": ".model.lattice",
    "CLG": ".clg.model",
    "Cline": ".algebra.mobius",
    "Direction": ".model.lattice",
    "Evaluation": ".model.lattice",
    "FieldSolid": ".clg.field",
    "FilteredLattice": ".filters",
    "FourierField": ".filters",
    "Identity": ".algebra.similarity",
    "ImplicitFilter": ".filters",
    "Lattice": ".model.lattice",
    "LiL": ".filters",
    "Mobius": ".algebra.mobius",
    "Node": ".model.lattice",
    "PleError": ".errors",
    "Pt": ".algebra.vectors",
    "Range": ".program.runtime",
    "RectifiedWarp": ".model.warp",
    "Region": ".model.lattice",
    "Rotation": ".algebra.similarity",
    "Scaling": ".algebra.similarity",
    "Screw": ".algebra.similarity",
    "ShapeOntoCone": ".model.planar",
    "Similarity": ".algebra.similarity",
    "SteadyMap2": ".model.planar",
    "Stencil": ".filters",
    "Swirl": ".algebra.similarity",
    "TMIMap": ".model.mobius",
    "TPMSField": ".filters",
    "Translation": ".algebra.similarity",
    "Vec": ".algebra.vectors",
    "becots_lattice": ".model.becots_builders",
    "compile_program": ".program.runtime",
    "lil": ".filters",
    "load_clg": ".program.clg_sources",
    "load_ir": ".io.irfile",
    "load_lattice": ".program.sources",
    "mobius_frames_lattice": ".model.mobius",
    "mobius_lattice": ".model.mobius",
    "rectified_warp": ".model.warp",
    "save_ir": ".io.irfile",
    "set_field": ".model.becots_builders",
    "snap_corner": ".model.planar",
    "stack_lattice": ".model.becots_builders",
    "with_control_frames": ".model.mobius",
}


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


def __getattr__(name: str):
    """The program API's names, imported from their layer on first use."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'ple' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
