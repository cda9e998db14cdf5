"""Meshes made in a child process (``runner.Job``): manifold3d's Booleans run in C and hold the
interpreter for as long as they take, so a signal handled in Python would wait for them. Here
Ctrl-C, SIGTERM and SIGHUP (which unwind the parent as ``KeyboardInterrupt``) kill the child at
once; nothing it made is kept."""

from __future__ import annotations

import numpy as np

from ..meshing.clg import check_budget, mesh_arrays
from .runner import Job


def mesh_clg_contained(comp, segments: int, max_bytes: float | None, name: str,
                       memory: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``ple.meshing.clg.mesh_arrays`` of a compiled CLG (``ple.clg.query.Compiled``, nested
    materials included) in a child process with no time limit. The budget (``check_budget``) is
    checked first, before the child starts. ``name`` names the source in errors; ``memory``, if
    given, caps the child's address space. Returns vertices (V, 3) and faces (F, 3)."""
    check_budget(comp, segments, max_bytes)
    return Job(lambda: mesh_arrays(comp, segments, max_bytes), name, None, memory, what="the CLG mesh").result()
