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


def core(name: str) -> ModuleType:
    """A core sub-module, e.g. ``core("cage")``."""
    return importlib.import_module(f"{ple.__name__}.{name}")


def optional(name: str) -> ModuleType | None:
    """A core sub-module that may not exist in this version (None), e.g. ``tessellate``.
    If it exists but needs a package Blender's Python lacks (trimesh, scipy), that is a
    PleError naming the package, reported to the user instead of a traceback."""
    try:
        return core(name)
    except ModuleNotFoundError as exc:
        if exc.name == f"{ple.__name__}.{name}":
            return None
        raise ple.PleError(f"ple.{name} needs the Python package {exc.name!r}, which Blender's Python "
                           "does not have (install it into Blender's Python to use this)") from None


cage = core("cage")
guard = core("guard")
ir = core("ir")
program = core("program")
snippets = core("snippets")
PleError = ple.PleError
Lattice = ple.Lattice
Similarity = ple.Similarity
