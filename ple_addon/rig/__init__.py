"""The rig: Blender objects that show and edit one lattice (thesis §6.2.2, Fig. 6.1–6.2).

``model`` reads a rig as a core lattice (Blender state -> ``ple.Lattice``), ``edits`` reads the
user's moves as GUI edits, ``drawing`` writes a lattice's drawing into the rig's objects,
``sync`` redraws a rig when it changed and makes, copies and removes rigs, ``events`` holds the
update callbacks and application handlers, and ``hooks`` is where features plug in (the rig
never imports a feature)."""

from __future__ import annotations

from . import drawing, edits, events, hooks, model, sync

MODULES = (hooks, model, edits, drawing, sync, events)


def register() -> None:
    for m in MODULES:
        m.register()


def unregister() -> None:
    for m in reversed(MODULES):
        m.unregister()
