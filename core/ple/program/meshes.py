"""Meshes made in a child process (``runner.Job``): manifold3d's Booleans run in C and hold the
interpreter for as long as they take, so a signal handled in Python would wait for them. Here
Ctrl-C, SIGTERM and SIGHUP (which unwind the parent as ``KeyboardInterrupt``) kill the child at
once; nothing it made is kept. The child sends back vertices and faces only (numpy arrays pass
the runner's allowlist)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..meshing.clg import check_outer_budget, mesh_arrays
from .runner import Job

if TYPE_CHECKING:  # imported where used: a run that writes no mesh object pays no trimesh import
    import trimesh


def mesh_clg_contained(comp, segments: int, max_bytes: float | None, name: str,
                       memory: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``ple.meshing.clg.mesh_arrays`` of a compiled CLG (``ple.clg.query.Compiled``, nested
    materials included) in a child process with no time limit. The budget of its leaves
    (``check_outer_budget``) is checked first, before the child starts; the child checks the
    rest. ``name`` names the source in errors; ``memory``, if given, caps the child's address
    space. Returns vertices (V, 3) and faces (F, 3)."""
    check_outer_budget(comp, segments, max_bytes)
    return Job(lambda: mesh_arrays(comp, segments, max_bytes), name, None, memory, what="the CLG mesh").result()


def mesh_contained(make: Callable[[], trimesh.Trimesh], name: str, what: str) -> trimesh.Trimesh:
    """The mesh ``make()`` returns (``ple.meshing.skin.skin``, …), made in a child process with no
    time limit; ``name`` and ``what`` ("the skin") name it in errors. Its vertices (V, 3) and faces
    (F, 3) come back as they were made (``process=False``)."""
    import trimesh
    def arrays():
        mesh = make()
        return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)

    verts, faces = Job(arrays, name, None, None, what=what).result()
    return trimesh.Trimesh(verts, faces, process=False)
