"""What makes a rig live: the update callbacks of its settings (region, counts, Cumulative,
filters) and the application handlers (``depsgraph_update_post`` for moved frames, bodies and
Möbius frames; ``load_post``, ``undo_post``, ``redo_post`` and ``save_post`` for the session).
In background mode msgbus and timers never fire: everything live goes through these."""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from ..corelink import PleError, cage, snippets
from ..session import SESSION
from . import hooks, sync
from .model import (
    add_edits,
    all_rigs,
    check_budget,
    dependents,
    edits_of,
    is_rig,
    lattice_of,
    programs,
    region_of,
    rig_of,
)


def set_quietly(settings, **values) -> None:
    """Set several settings (of ``rig.ple`` or a feature's group) with no update callback run."""
    with SESSION.quiet():
        for k, v in values.items():
            setattr(settings, k, v)


# ----- settings ------------------------------------------------------------------------------------
def on_settings_changed(rig) -> None:
    """A setting of the panel changed; a region beyond the work budget (or otherwise bad) is
    refused: the region settings go back to the last drawn ones, the error stays the status."""
    if SESSION.busy or not is_rig(rig):
        return
    st = SESSION.state(rig.ple.uid)
    err = sync.refresh(rig)
    if err and st.region and (tuple(rig.ple.region_min), tuple(rig.ple.region_max)) != st.region:
        set_quietly(rig.ple, region_min=st.region[0], region_max=st.region[1])
        sync.refresh(rig, force=True)
        sync.refuse(rig, err, report=False)  # refresh reported it already
    refresh_dependents(rig)


def on_cumulative_changed(rig) -> None:
    """The Cumulative toggle only changes what a frame shows; a stored frame edit is re-expressed
    in the shown form (incremental <-> cumulative), so a later count change keeps what the
    user sees (the step, or the span from group 0 to the last group)."""
    if SESSION.busy or not is_rig(rig):
        return
    lat = SESSION.state(rig.ple.uid).lattice
    if lat is not None:
        try:
            edits = edits_of(rig)
            for n, axis in enumerate("uvw"):
                flag = bool(rig.ple.cumulative[n])
                for i, e in enumerate(edits):
                    if (isinstance(e, snippets.SetDirection) and e.axis == axis and e.similarity is not None
                            and e.cumulative != flag):
                        count = getattr(lat, axis).count
                        sim = cage.direction_similarity(lat, axis, flag)
                        edits[i] = snippets.SetDirection(axis, e.count, sim, flag and count > 1)
            set_quietly(rig.ple, edits=snippets.edits_to_json(edits))
        except PleError as exc:
            rig.ple.status = str(exc)
    on_settings_changed(rig)


def count_edit(lat, axis: str, count: int, cumulative: bool):
    """The count slider's edit of ``axis``: it keeps what the frame shows. A frame showing the
    cumulative similarity keeps it, the span from group 0 to the last group (the step follows),
    whether or not it was dragged; otherwise the count alone changes (the step, or a span the
    program itself wrote with ``cumulative=True``, is kept)."""
    if count > 1 and cage.shows_cumulative(lat, axis, cumulative):
        return snippets.SetDirection(axis, count, cage.direction_similarity(lat, axis, True), True)
    return snippets.SetDirection(axis, count)


def on_counts_changed(rig) -> None:
    """The counts slider: a set_u/v/w edit per changed direction (``count_edit``). Counts the core
    refuses (absurd, or a region beyond the work budget) are not stored: the slider goes back
    and the reason is the status."""
    if SESSION.busy or not is_rig(rig):
        return
    st = SESSION.state(rig.ple.uid)
    if st.lattice is None:
        return
    old_counts = st.lattice.counts
    edits = [count_edit(st.lattice, axis, int(c), rig.ple.cumulative[n])
             for n, (axis, c, old) in enumerate(zip("uvw", rig.ple.counts, old_counts)) if int(c) != old]
    try:
        lat = lattice_of(rig, st, edits)
        lat.validate()
        r = region_of(rig, lat)
        if r is not None:
            check_budget(lat, r)
        add_edits(rig, edits)
    except PleError as exc:
        asked = tuple(int(c) for c in rig.ple.counts)
        set_quietly(rig.ple, counts=old_counts)
        sync.refuse(rig, f"counts {asked} kept: {exc}")
        return
    sync.refresh(rig, live=True)  # a slider dragged: a big region shows its hull until the drag pauses
    refresh_dependents(rig)


def apply_filter(rig, settings: dict, prepared=None) -> str | None:
    """Set the panel's filter ``settings`` and redraw (``prepared``: what a job computed for them,
    see ``refresh``); on error the previous settings and drawing come back and the error is
    returned. Rigs filtered by this one follow."""
    old = {k: tuple(v) if k == "stencil_shape" else v for k, v in ((k, getattr(rig.ple, k)) for k in settings)}
    set_quietly(rig.ple, **settings)
    err = sync.refresh(rig, force=True, prepared=prepared)
    if err:
        set_quietly(rig.ple, **old)
        sync.refresh(rig, force=True)
        return err
    refresh_dependents(rig)
    return None


def refresh_dependents(rig) -> None:
    for dep in dependents(rig):
        sync.refresh(dep)


# ----- handlers ------------------------------------------------------------------------------------
def updated_objects(depsgraph) -> list:
    """The objects an update names, looked up by name in ``bpy.data``: an object deleted by the
    update is not there (its evaluated copy's ``original`` then points to freed memory, and
    reading it crashes Blender or returns garbage)."""
    out = {}
    for u in depsgraph.updates:
        if isinstance(u.id, bpy.types.Object):
            obj = bpy.data.objects.get(u.id.name)
            if obj is not None:
                out[obj.as_pointer()] = obj
    return list(out.values())


def rigs_in_updates(objects) -> list:
    """Rigs touched by an update (of ``objects``), then the rigs whose LiL filter depends on them."""
    found = {}
    for obj in objects:
        if obj.ple.role not in ("RIG", "FRAME", "NODE", "CORNER"):
            continue
        rig = rig_of(obj)
        if rig is not None:
            found[rig.as_pointer()] = rig
    for rig in list(found.values()):
        for dep in dependents(rig):
            found.pop(dep.as_pointer(), None)
            found[dep.as_pointer()] = dep  # after its coarse rig
    return list(found.values())


def check_removed(scene) -> None:
    """After the scene's objects changed in number: remove the parts of rigs whose lattice object
    is gone. Any change counts, not only fewer objects: a rig built and its lattice object deleted
    with no update in between (by a script, say) leaves more objects than the last update saw.
    None: not counted since a load, undo or redo."""
    n = len(scene.objects)
    if SESSION.object_count is not None and n != SESSION.object_count:
        sync.remove_orphans()
        n = len(scene.objects)
    SESSION.object_count = n


@persistent
def on_depsgraph_update(scene, depsgraph):
    """The add-on's one depsgraph handler. The updates are read, by name, before anything is
    deleted: removing a deleted rig's parts frees objects the update list still names."""
    objects = updated_objects(depsgraph)
    names = [r.name for r in rigs_in_updates(objects)]
    names += [name for fn in hooks.each("watchers") for name in fn(objects)]  # e.g. rigs whose body moved
    check_removed(scene)  # parts of a rig whose lattice object was deleted go with it
    for name in dict.fromkeys(names):
        r = bpy.data.objects.get(name)
        if is_rig(r):
            sync.refresh(r, live=True)
    for fn in hooks.each("updates"):  # e.g. Möbius rigs whose control frames moved
        fn(scene)


@persistent
def on_load_pre(*_args):
    """The open file is left (for another file, or File › New): its trusts are kept for the
    programs it holds on disk."""
    SESSION.keep_trust(bpy.data.filepath, SESSION.on_disk)


@persistent
def on_load(*_args):
    """Trust belongs to the file it was given in and to the program trusted: reopening that file,
    even after File › New, keeps it for the rigs whose program is still the one trusted; another
    .blend (even a copy holding the same rig ids) or a program changed on disk trusts nothing."""
    SESSION.restore_trust(bpy.data.filepath, programs())
    sync.resync()


@persistent
def on_save(filepath="", *_args):
    """A file saved holds the trusts of its rigs' programs (a file saved under a new name, or as a
    copy, carries them)."""
    now = programs()
    SESSION.keep_trust(filepath or bpy.data.filepath, now)
    if not filepath or filepath == bpy.data.filepath:  # not a copy: the open file's programs on disk
        SESSION.on_disk = now


@persistent
def on_reset(*_args):
    sync.resync()


HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("undo_post", on_reset), ("redo_post", on_reset),
            ("load_pre", on_load_pre), ("load_post", on_load), ("save_post", on_save))


def resume() -> None:
    """The add-on was enabled in a running session (its properties and hooks registered): the rigs
    are live again, their parts' places the baseline. At Blender's start ``bpy.data`` is not yet
    readable; ``load_post`` does this then."""
    if isinstance(bpy.data, bpy.types.BlendData) and all_rigs():
        sync.resync()


def register() -> None:
    for name, fn in HANDLERS:
        getattr(bpy.app.handlers, name).append(fn)


def unregister() -> None:
    for name, fn in HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if fn in handlers:
            handlers.remove(fn)
