"""The one place the add-on reaches the core package ``ple``.

Inside the installed extension the core is the vendored sub-package ``vendor.ple`` (relative,
so Blender's global ``sys.path`` is never touched); from a source checkout the ``ple`` that is
installed in the Python environment is used instead.
"""

from __future__ import annotations

import importlib
from types import ModuleType

try:
    from .vendor import ple
except ImportError:  # running from the source tree: the core is installed in the environment
    import ple


PleError = ple.PleError


def core(name: str) -> ModuleType:
    """A core sub-module, e.g. ``core("model.cage")``."""
    return importlib.import_module(f"{ple.__name__}.{name}")


def needs(name: str) -> ModuleType:
    """A core sub-module that imports a package Blender's Python may lack (trimesh, scipy),
    e.g. ``meshing.tessellate``: a missing package is a PleError naming it, reported to the
    user instead of a traceback."""
    try:
        return core(name)
    except ModuleNotFoundError as exc:
        raise missing(exc, f"ple.{name}") from None


def missing(exc: ModuleNotFoundError, what: str = "this") -> PleError:
    """The report of a package Blender's Python lacks, found where the core imports it (trimesh
    is imported where a mesh object is made, so a module loads without it)."""
    return ple.PleError(f"{what} needs the Python package {exc.name!r}, which Blender's Python does not have "
                        "(install it into Blender's Python to use this)")


body = core("filters.body")  # bodies and the body filter (the Body panel)
cage = core("model.cage")
cleanup = core("filters.cleanup")
files = core("io.files")  # outputs written atomically: complete or not at all
grading = core("model.grading")  # radius fields: graded thickness
ir = core("filters.ir")  # ple-lattice/1 data with filters
irfile = core("io.irfile")  # ple-lattice/1 files: a body mesh resolved against its folder
precision = core("algebra.precision")  # numbers read off float32 frames
presets = core("program.presets")
program = core("program.runtime")
runner = core("program.runner")  # programs and long core work contained in a child process
snippets = core("program.snippets")
styles = core("meshing.styles")  # also the triangle estimate of a style
weld = core("meshing.weld")  # meshes that survive float32 (files, Blender meshes)
work = core("model.budget")  # the work budget: estimates of a region (balls, beams, triangles, memory), limits
Lattice = ple.Lattice
Similarity = ple.Similarity


def register() -> None:
    pass


def unregister() -> None:
    pass
