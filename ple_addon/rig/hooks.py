"""What features plug into the rig (the rig never imports a feature): each feature adds its
functions here in its ``register()`` and takes them out in ``unregister()``.

- ``loaders``: ``fn(rig, source, params, name)`` -> (inputs, lattice) or None, for a rig whose text
  is not a lattice program (a CLG rig: its pattern);
- ``shown``: ``fn(rig, lat, region)`` -> lattice, the lattice as the panels show it (a body's
  grading, fill and cleanup);
- ``filtering``: ``fn(rig)`` -> bool, true when the drawing is not the plain evaluation (the fast
  redraw path is then off);
- ``signatures``: ``fn(rig)`` -> tuple, more things a drawing depends on (a body's mesh and place);
- ``after_draw``: ``fn(rig, lat)``, after every successful drawing (a CLG rig's preview);
- ``watchers``: ``fn(objects)`` -> rig names, rigs to redraw when other objects changed (bodies,
  gradient empties);
- ``updates``: ``fn(scene)``, on every depsgraph update (Möbius rigs);
- ``appliers``: ``fn(rig)`` -> new text or None, Apply to Program of a text that is not a lattice
  program (a ``ple-clg/1`` file);
- ``routes``: ``fn(preset)`` -> operator idname or None, presets that another operator adds (the
  Möbius presets);
- ``meshed``: ``fn(obj)`` -> (rig, fn() -> (lattice, region)) or None, objects of a rig that is not a
  steady rig but that Tessellate and Export mesh (a Möbius rig).
"""

from __future__ import annotations

HOOKS: dict[str, list] = {name: [] for name in ("loaders", "shown", "filtering", "signatures", "after_draw",
                                                "watchers", "updates", "appliers", "routes", "meshed")}


def add(name: str, fn) -> None:
    if fn not in HOOKS[name]:
        HOOKS[name].append(fn)


def remove(name: str, fn) -> None:
    if fn in HOOKS[name]:
        HOOKS[name].remove(fn)


def first(name: str, *args):
    """The first answer that is not None of the functions of hook ``name``, or None."""
    for fn in HOOKS[name]:
        out = fn(*args)
        if out is not None:
            return out
    return None


def each(name: str):
    return tuple(HOOKS[name])


def register() -> None:
    pass


def unregister() -> None:
    for fns in HOOKS.values():
        fns.clear()
