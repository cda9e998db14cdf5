"""PLE — Programmed Lattice Editor for Blender (thesis §6.2, SPEC §7).

A thin skin over the core package ``ple``: frames (empties) that define the placement G and
the similarities U, V, W, a cage of isocurves, a fully drawn index region, template editing,
code snippets of GUI edits, filters, tessellation and export. Live editing runs in a
``depsgraph_update_post`` handler (msgbus and timers do not fire in background mode).

The layers, bottom up (docs/architecture.md): ``corelink`` (the one door into the core),
``prefs``; ``session``, ``draw``, ``jobs``; ``rig`` (hooks, model, edits, sync, events);
``props``, ``ops`` (base, then program, template, output), ``ui``; ``features`` (body, clg,
mobius, check). Every module registers its own classes and hooks.
"""

from __future__ import annotations

from . import corelink, draw, jobs, ops, prefs, props, rig, session, ui
from .features import body, check, clg, mobius
from .rig import events

MODULES = (corelink, prefs, session, draw, jobs, rig, props, ops, ui, check, body, clg, mobius)


def register():
    for m in MODULES:
        m.register()
    events.resume()


def unregister():
    for m in reversed(MODULES):
        m.unregister()
