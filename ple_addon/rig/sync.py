"""A core lattice drawn as a rig (``ple.Lattice`` -> Blender objects): ``refresh`` reads the user's
moves (``edits``), evaluates the rig (``model``) and writes the frames, template nodes, corners,
cage and region (``draw``); creating, copying and removing rigs.

Errors (a bad program, a degenerate frame) leave the program text, the edits and the last good
drawing untouched and are shown as the rig's status (and reported to the Info editor).
"""

from __future__ import annotations

import uuid

import bpy
import numpy as np
from mathutils import Vector

from .. import draw
from ..corelink import PleError, snippets
from ..session import SESSION, RigState, notify
from . import hooks
from .drawing import KEPT, draw_rig, handle_size, new_part
from .edits import baseline, user_edits
from .model import (
    PARAM_PREFIX,
    PART_ROLES,
    Drawn,
    add_edits,
    all_rigs,
    base_lattice,
    check_budget,
    evaluate_region,
    lattice_of,
    moves_rigidly,
    parts,
    rig_of,
    signature,
    trust,
    trusted,
    uid,
)

PARTS = {"G", "u", "v", "w", "cage", "region"}  # what every rig has (template nodes and corners come and go)


def refresh(rig, force: bool = False, prepared=None, live: bool = False) -> str | None:
    """Read user moves, re-evaluate and redraw if anything changed; returns an error or None.
    ``prepared``: (lattice, evaluation) a job computed for the rig as it is now, drawn instead
    of evaluating again unless the user moved something since. ``live``: a move in progress
    (the depsgraph handler): a region of more than ``drawing.LIVE_ELEMENTS`` is drawn as its hull until
    the moves pause (``settle``). A move of G alone, where the drawing moves rigidly, moves the
    region's object and rewrites nothing.

    Errors (bad program, degenerate frame) leave the program text, the edits and the last
    good drawing untouched and are shown as the rig's status; a refused setting (``refuse``)
    stays shown until the user's next edit."""
    if SESSION.busy:
        return None
    claim(rig)
    st = SESSION.state(uid(rig))
    with SESSION.quiet():
        try:
            if st.lattice is None and st.expected:  # moves made before the program could run
                st.lattice = lattice_of(rig, st)
            new = user_edits(rig, st)
            if not new and not force and signature(rig) == st.signature and st.lattice is not None:
                if rig.ple.status and not st.refused:  # e.g. a degenerate frame was put back
                    rig.ple.status = ""
                return None
            placed_only = (st.rigid and new and not force and prepared is None and signature(rig) == st.signature
                           and all(isinstance(e, snippets.SetPlacement) for e in new)
                           and PARTS <= set(parts(rig)))  # a drawing to keep (not parts built again)
            if prepared is not None and not new:  # a job's evaluation (a filter's), in the rig's coordinates
                lat, ev = prepared
                ev, at = (None if ev is None else Drawn.of(ev)), np.eye(4)
            else:
                lat = lattice_of(rig, st, new)  # new edits are kept only if the lattice they give is valid
                if placed_only and moves_rigidly(rig, lat):
                    ev, at = KEPT, lat.placement.matrix
                else:
                    ev, at = evaluate_region(rig, lat, st)
        except PleError as exc:
            if rig.ple.status != str(exc):
                notify(rig, str(exc))
            rig.ple.status, st.refused = str(exc), False
            return str(exc)
        add_edits(rig, new)
        st.lattice = lat
        if not PARTS <= set(parts(rig)):
            build_parts(rig, lat)  # a copy (Shift+D) or a rig whose parts were deleted
        if draw_rig(rig, lat, ev, st, at, live):
            _settle_later()
        for hook in hooks.each("after_draw"):  # e.g. a CLG rig's preview
            hook(rig, lat)
        st.signature = signature(rig)
        st.cumulative = tuple(rig.ple.cumulative)
        st.region = (tuple(rig.ple.region_min), tuple(rig.ple.region_max))
        if st.clamped:  # an input beyond its Range was clamped: said until the user's next edit
            refuse(rig, st.clamped)
            st.clamped = ""
            return None
        st.refused = False
        if rig.ple.status:
            rig.ple.status = ""
        return None


SETTLE_SECONDS = 0.3  # moves paused this long (the mouse released): the region drawn in full


def settle() -> None:
    """The moves paused: every rig drawn as its hull is drawn in full (a timer, ``SETTLE_SECONDS``
    after the last live move; a background session, where timers never fire, calls it)."""
    for r in all_rigs():
        st = SESSION.states.get(uid(r))
        if st is not None and st.hull_drawn:
            st.hull_drawn = False
            refresh(r, force=True)


def _settle_later() -> None:
    if bpy.app.timers.is_registered(settle):
        bpy.app.timers.unregister(settle)  # the last move counts: the pause starts now
    bpy.app.timers.register(settle, first_interval=SETTLE_SECONDS)


def note(rig, message: str) -> None:
    """A word on the rig's last result (the unclean hubs a mesh united locally): its status until
    the user's next edit, as a refusal's is."""
    rig.ple.status = message
    SESSION.state(uid(rig)).refused = True


def refuse(rig, message: str, report: bool = True) -> None:
    """A setting the user made was refused and set back (a region beyond the work budget, absurd
    counts): ``message`` is the rig's status, and a report, until the user's next edit."""
    rig.ple.status = message
    SESSION.state(uid(rig)).refused = True
    if report:
        notify(rig, message)


# ----- building a rig -------------------------------------------------------------------------
def mesh_part(rig, role: str, material):
    """The rig's mesh part of ``role`` (e.g. "CLG": a preview), made once (``NAME.role``, not
    selectable, with ``material``)."""
    obj = parts(rig).get(role.lower())
    if obj is None:
        name = f"{rig.name}.{role.lower()}"
        obj = new_part(rig, name, bpy.data.meshes.new(name), role)
        obj.hide_select = True
        draw.set_material(obj, material)
    return obj


def set_params(rig, inputs) -> None:
    """Program inputs (``runtime.Param``) as custom properties with slider ranges (``Range(lo, hi)``).
    A slider the rig has keeps its value (the user's); its range and default follow the program, so
    Blender's Reset to Default Value gives the program's default. A new input gets its default."""
    for prm in inputs:
        key = PARAM_PREFIX + prm.name
        if key not in rig:
            rig[key] = prm.default
        if isinstance(prm.default, (int, float)) and not isinstance(prm.default, bool):
            ui = rig.id_properties_ui(key)
            opts = {"description": f"program input {prm.name} of lattice()", "default": prm.default}
            if prm.range is not None:
                kind = type(prm.default)  # an int input gets int limits
                lo, hi = kind(prm.range.lo), kind(prm.range.hi)
                opts.update(min=lo, max=hi, soft_min=lo, soft_max=hi)
            ui.update(**opts)


def build_parts(rig, lat) -> None:
    """The frames G, U, V, W, the cage and the region of a rig, those it lacks (template nodes
    and BeCOTS corners are made by the drawing)."""
    name = rig.name
    size = handle_size(lat)
    have = parts(rig)
    g = have.get("G")
    if g is None:
        g = new_part(rig, f"{name}.G", None, "FRAME")
        g.ple.frame, g.empty_display_type, g.empty_display_size = "G", "ARROWS", 1.5 * size
    for axis in "uvw":
        if axis not in have:
            f = new_part(rig, f"{name}.{axis.upper()}", None, "FRAME", parent=g)
            f.ple.frame, f.empty_display_type, f.empty_display_size = axis, "ARROWS", size
    if "cage" not in have:
        cage_obj = new_part(rig, f"{name}.cage", draw.new_cage_curve(f"{name}.cage", lat), "CAGE")
        cage_obj.hide_select = True
        draw.set_material(cage_obj, draw.CAGE_MATERIAL)
    if "region" not in have:
        region_obj = new_part(rig, f"{name}.region", draw.new_region_mesh(f"{name}.region"), "REGION")
        region_obj.hide_select = True
        draw.add_balls_beams_modifier(region_obj)
        draw.set_material(region_obj, draw.REGION_MATERIAL)


def create(context, name: str, text, source_kind: str = "PROGRAM", region=(3, 3, 3), location=None,
           clg: bool = False, folder: str = ""):
    """Build a rig for ``text`` (a Text datablock) at ``location`` (default: the 3D cursor);
    raises PleError before creating anything if the program or IR is bad or the region is
    beyond the work budget. With ``clg``, ``text`` holds a CLG and the rig edits its pattern;
    ``folder`` is where a body mesh the IR names is found."""
    st = RigState()
    probe = bpy.data.objects.new("~ple probe", None)  # evaluate before building anything
    try:
        probe.ple.text, probe.ple.source_kind, probe.ple.folder = text, source_kind, folder
        probe.ple_clg.active = clg
        SESSION.trusted.add(uid(probe))
        base = base_lattice(probe, st)
        inputs = st.inputs
        size = tuple(min(r, c) for r, c in zip(region, base.counts))
        start = base.first_kept_group() or (0, 0, 0)  # a filter keeping nothing at the origin: where it keeps
        lo = tuple(max(0, min(s, c - n)) for s, c, n in zip(start, base.counts, size))
        hi = tuple(a + n for a, n in zip(lo, size))
        check_budget(base, ",".join(f"{a}:{b}" for a, b in zip(lo, hi)), "drawing the region")
    finally:
        SESSION.trusted.discard(uid(probe))
        bpy.data.objects.remove(probe)
    coll = bpy.data.collections.new(f"PLE {name}")
    context.scene.collection.children.link(coll)
    rig = bpy.data.objects.new(name, None)
    coll.objects.link(rig)
    rig.location = context.scene.cursor.location if location is None else location
    rig.empty_display_type = "PLAIN_AXES"
    rig.empty_display_size = handle_size(base)
    rig.ple.role = "RIG"
    rig.ple.text, rig.ple.source_kind, rig.ple.folder = text, source_kind, folder
    rig.ple_clg.active = clg
    rig.ple.region_min, rig.ple.region_max = lo, hi
    trust(rig)
    claim(rig)
    if inputs is not None:
        set_params(rig, inputs)
    build_parts(rig, base)
    SESSION.states[uid(rig)] = st
    err = refresh(rig, force=True)
    if err:
        raise PleError(err)
    return rig


def remove(rig) -> None:
    """Delete a rig's objects and its own datablocks (meshes, curves), keeping the program text."""
    objs = [rig, *rig.children_recursive]
    data = [o.data for o in objs if o.data is not None and o.data.users <= 1]
    colls = [c for c in rig.users_collection if c.name.startswith("PLE ")]
    SESSION.states.pop(rig.ple.uid, None)
    SESSION.owner.pop(rig.ple.uid, None)
    bpy.data.batch_remove(objs + data)
    for c in colls:
        if not c.objects and not c.children:
            bpy.data.collections.remove(c)


def remove_orphans() -> int:
    """Delete parts whose rig is gone (the user deleted only the lattice object: Blender keeps
    it in memory, unlinked, while its parts point to it); returns how many objects went."""
    gone = [o for o in bpy.data.objects if o.ple.role == "RIG" and not o.users_collection]
    orphans = [o for o in bpy.data.objects if o.ple.role in PART_ROLES and (rig_of(o) is None or rig_of(o) in gone)]
    for rig in gone:
        SESSION.states.pop(rig.ple.uid, None)
    orphans += gone
    if orphans:
        data = [o.data for o in orphans if o.data is not None and o.data.users <= 1]
        bpy.data.batch_remove(orphans + data)
    return len(orphans)


def claim(rig) -> None:
    """Register the rig's stable id; a rig holding another object's id is a copy (Shift+D):
    it gets its own id, its own program text (a copy), the original's trust, and parts of its own."""
    key = uid(rig)
    owner = SESSION.owner.get(key)
    if owner is None or owner == rig.session_uid:
        SESSION.owner[key] = rig.session_uid
        return
    if not any(o.session_uid == owner and o.ple.uid == key for o in all_rigs()):
        SESSION.owner[key] = rig.session_uid  # the holder is gone (deleted, or a new session)
        return
    make_independent(rig, was_trusted=key in SESSION.trusted)


def make_independent(rig, was_trusted: bool) -> None:
    rig.ple.uid = uuid.uuid4().hex
    SESSION.owner[rig.ple.uid] = rig.session_uid
    if was_trusted:
        SESSION.trusted.add(rig.ple.uid)
    if rig.ple.text is not None:
        rig.ple.text = rig.ple.text.copy()
    rig.ple.filepath = ""  # the copy's program is not the original's file on disk
    old = list(rig.children_recursive)  # duplicated parts (if they were selected) still point elsewhere
    if old:  # the next drawing builds the copy's own parts (once its program may run)
        data = [o.data for o in old if o.data is not None and o.data.users <= 1]
        bpy.data.batch_remove(old + data)


def duplicate(context, rig):
    """A copy of a rig with its own program text, trust and parts, one handle size along U."""
    lat = lattice_of(rig)
    copy = rig.copy()
    for coll in rig.users_collection:
        coll.objects.link(copy)
    copy.parent = rig.parent
    cage_obj = parts(rig).get("cage")
    width = cage_obj.dimensions.x if cage_obj is not None and cage_obj.dimensions.x > 0 else 5 * handle_size(lat)
    copy.location = rig.location + Vector((1.25 * width, 0, 0))  # beside the original, not on it
    make_independent(copy, was_trusted=trusted(rig))
    SESSION.states.pop(copy.ple.uid, None)
    err = refresh(copy, force=True)
    if err:
        raise PleError(err)
    return copy




def resync() -> None:
    """Forget what was drawn and take every rig's parts as they are now as the baseline, then
    redraw (after undo, redo, loading a file, and enabling the add-on in a running session:
    the positions are the saved state, not user moves; moves made before Run Program still count)."""
    SESSION.forget_drawn()
    for r in all_rigs():
        claim(r)
        baseline(r)
    for r in all_rigs():
        refresh(r, force=True)


def register() -> None:
    pass


def unregister() -> None:
    pass
