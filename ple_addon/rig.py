"""The rig: Blender objects that show and edit one lattice (thesis §6.2.2, Fig. 6.1–6.2).

A rig is a collection holding the lattice object (an empty, ``obj.ple.role == "RIG"``, whose
program lives in a Text datablock and whose inputs are custom properties ``ple:<name>``),
the placement frame G (child of the rig), the frames U, V, W and the template nodes
(children of G), the cage (curves) and the region (vertices at ball centres, edges for
beams, drawn as balls and cone-beams by a geometry-nodes modifier). Everything geometric is
computed by the core; this module only moves numbers between Blender and ``ple``.
"""

from __future__ import annotations

import json
import uuid
from dataclasses import dataclass, field

import bpy
import numpy as np
from mathutils import Matrix, Vector

from . import body_panel, draw, jobs, prefs
from .corelink import PleError, cage, core, ir, precision, snippets, work

PARAM_PREFIX = "ple:"
FRAME_NAMES = ("G", "u", "v", "w")
MOVE_TOL = 1e-6  # a frame or node counts as moved by the user beyond this (float32 matrices)
_trusted: set[str] = set()  # stable ids (obj.ple.uid) of rigs whose program the user ran in this session
_owner: dict[str, int] = {}  # stable id -> session_uid of the object that holds it (a copy has another)
_busy = False  # set while the add-on itself writes to the rig (update callbacks stay quiet)


@dataclass
class RigState:
    """What the add-on last drew for a rig, to tell user moves from its own writes."""

    program_key: tuple = ()
    inputs: list | None = None  # the program's inputs (runtime.Param), as its child process gave them
    base: object = None
    lattice: object = None
    expected: dict = field(default_factory=dict)
    signature: tuple = ()
    topology: tuple = ()  # (key, Evaluation) of the last unfiltered region drawn
    cumulative: tuple = (False, False, False)  # the Cumulative toggles when last drawn
    region: tuple = ()  # (region_min, region_max) last drawn without error


_state: dict[str, RigState] = {}
AFTER_DRAW: list = []  # functions (rig, lattice) run after every successful drawing of a rig


def clear_state() -> None:
    """Forget drawn state (after undo or file load: positions are then not user moves)."""
    _state.clear()
    _owner.clear()


def uid(rig) -> str:
    """The rig's stable id (kept through renames and file saves; a duplicate gets its own)."""
    if not rig.ple.uid:
        rig.ple.uid = uuid.uuid4().hex
    return rig.ple.uid


def state_of(rig) -> RigState:
    return _state.setdefault(uid(rig), RigState())


def baseline(rig) -> None:
    """Take the parts' current matrices as what was drawn (after loading a file or undo), so
    that moves made before the program can run are still read as user moves later."""
    st = state_of(rig)
    for key, obj in parts(rig).items():
        if key in FRAME_NAMES or (isinstance(key, tuple) and key[0] in ("node", "corner")):
            st.expected[key] = _flat(obj.matrix_basis)
    st.cumulative = tuple(rig.ple.cumulative)


def is_rig(obj) -> bool:
    return obj is not None and obj.ple.role == "RIG"


def rig_of(obj):
    """The rig an object belongs to (itself if it is one), or None."""
    if obj is None:
        return None
    if obj.ple.role == "RIG":
        return obj
    return obj.ple.rig if obj.ple.rig is not None and obj.ple.rig.ple.role == "RIG" else None


def parts(rig) -> dict:
    """Parts of a rig by key: "G", "u", "v", "w", "cage", "region", "clg" (a CLG rig's preview),
    ("node", n), ("corner", c)."""
    out = {}
    for obj in rig.children_recursive:
        role = obj.ple.role
        if role == "FRAME":
            out[obj.ple.frame] = obj
        elif role == "NODE":
            out[("node", obj.ple.node_index)] = obj
        elif role == "CORNER":
            out[("corner", obj.ple.frame)] = obj
        elif role in ("CAGE", "REGION", "CLG"):
            out[role.lower()] = obj
    return out


# ----- the lattice of a rig -------------------------------------------------------------------
def params_of(rig) -> dict:
    return {k[len(PARAM_PREFIX):]: (v.to_dict() if hasattr(v, "to_dict") else v)
            for k, v in rig.items() if k.startswith(PARAM_PREFIX)}


def trusted(rig) -> bool:
    """Programs run only if Blender trusts scripts or the user ran this one explicitly (SPEC §9)."""
    return (rig.ple.source_kind == "IR" or uid(rig) in _trusted
            or bpy.context.preferences.filepaths.use_scripts_auto_execute)


def trust(rig) -> None:
    _trusted.add(uid(rig))
    _trust_file[0] = bpy.data.filepath


_trust_file = [""]  # the .blend the trusts were given in (a file saved under a new name carries them)


def trusted_file(path: str) -> None:
    _trust_file[0] = path


def forget_trust_of_other_files(path: str) -> None:
    if path != _trust_file[0]:
        _trusted.clear()
        _trust_file[0] = path


def base_lattice(rig, st: RigState):
    """The lattice the program (or IR) gives, before GUI edits; cached per text and inputs."""
    text = rig.ple.text
    if text is None:
        raise PleError(f"{rig.name}: the program text block is missing")
    source = text.as_string()
    params = params_of(rig)
    key = (rig.ple.source_kind, source, tuple(sorted((k, repr(v)) for k, v in params.items())))
    if key == st.program_key:
        return st.base
    if rig.ple.source_kind == "PROGRAM" and not trusted(rig):
        raise PleError(f"{text.name}: not run because Blender does not trust scripts "
                       "(enable Auto Run Python Scripts, or press Run Program; frame moves are "
                       "kept until then)")
    if rig.ple_clg.active:  # a CLG rig (clg_rig.py): the lattice is the CLG's pattern
        from . import clg_rig

        inputs, base = clg_rig.load(rig.ple.source_kind, source, params, text.name)
    elif rig.ple.source_kind == "IR":
        try:
            data = json.loads(source)
        except json.JSONDecodeError as exc:
            raise PleError(f"{text.name}: malformed JSON at line {exc.lineno}: {exc.msg}") from None
        base = ir.lattice_from_ir(data)
        inputs = None
    else:
        base, inputs = jobs.run_text(source, text.name, params)  # contained: time and memory limits
    st.program_key, st.inputs, st.base = key, inputs, base
    return base


def edits_of(rig) -> list:
    return snippets.edits_from_json(rig.ple.edits)


def add_edits(rig, new) -> None:
    if new:
        rig.ple.edits = snippets.edits_to_json(snippets.coalesce(edits_of(rig) + list(new)))


def lattice_of(rig, st: RigState | None = None, new=()):
    """The rig's current lattice: program (or IR) with its inputs, then the GUI edits (and
    ``new`` ones not yet stored)."""
    st = st if st is not None else state_of(rig)
    return snippets.apply_to_lattice(base_lattice(rig, st), edits_of(rig) + list(new))


def region_of(rig, lat):
    """The drawn index box, clamped to the lattice; None if empty."""
    lo = [min(a, c) for a, c in zip(rig.ple.region_min, lat.counts)]
    hi = [min(b, c) for b, c in zip(rig.ple.region_max, lat.counts)]
    if any(a >= b for a, b in zip(lo, hi)):
        return None
    return lat.region(f"{lo[0]}:{hi[0]},{lo[1]}:{hi[1]},{lo[2]}:{hi[2]}")


def in_rig_space(rig, other_rig, lat):
    """``lat`` of ``other_rig`` placed in the coordinates of ``rig`` (for LiL across rigs)."""
    rel = np.array(rig.matrix_world.inverted() @ other_rig.matrix_world)
    out = lat.copy()
    out.set_placement(cage.placement_from_frame(rel) @ lat.placement)
    return out


def filtered(rig, lat, space=None, _seen=()):
    """The core filter of the rig's Filters panel (None for none), in the coordinates of the
    rig ``space`` (default: ``rig``). A coarse lattice that is itself LiL-filtered makes a
    cascade (thesis Fig. 9.3): its own filter is built recursively; cycles are an error."""
    kind = rig.ple.filter_kind
    if kind == "NONE":
        return None
    filters = core("filters")
    if kind == "STENCIL":
        shape = tuple(rig.ple.stencil_shape)
        bits = rig.ple.stencil_bits.strip()
        n = int(np.prod(shape))
        if len(bits) != n or set(bits) - {"0", "1"}:
            raise PleError(f"stencil: expected {n} characters 0/1 for shape {shape}, got {bits!r}")
        return filters.Stencil(np.array([c == "1" for c in bits]).reshape(shape))
    return lil_filter(rig, rig.ple.coarse, space, _seen)


def lil_filter(rig, coarse, space=None, _seen=()):
    """The LiL filter of ``rig`` by the rig ``coarse`` (cascading through the coarse rig's own
    LiL), in the coordinates of ``space`` (default: ``rig``); the rig's settings are not read."""
    if not is_rig(coarse):
        raise PleError("LiL filter: choose a coarse PLE lattice object")
    if uid(coarse) in _seen or coarse == rig:
        raise PleError(f"LiL filter: {coarse.name} is coarse for itself through a cycle of LiL filters")
    space = rig if space is None else space
    coarse_lat = in_rig_space(space, coarse, lattice_of(coarse))
    inner = filtered(coarse, coarse_lat, space, (*_seen, uid(rig)))
    return core("filters").LiL(coarse_lat.with_filter(inner))


def evaluate_region(rig, lat, st: RigState | None = None):
    """Evaluation of the drawn region, through the program's and the panel's filters (None if
    the region is empty). Unfiltered, a move of a frame changes only ball centres and radii:
    the node and beam indices of the last evaluation are reused (``Lattice.region_balls``)."""
    r = region_of(rig, lat)
    if r is None:
        return None
    work.check(work.estimate(lat, r), max_bytes=prefs.max_bytes(), what=f"drawing region {r}")
    panel = filtered(rig, lat)
    if lat.filter is None and panel is None and not body_panel.active(rig):
        key = (str(r), len(lat.nodes), tuple((b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams))
        if st is not None and st.topology and st.topology[0] == key:
            last = st.topology[1]
            centers, radii = lat.region_balls(r)
            return type(last)(last.node_index, centers.reshape(-1, 3), radii.reshape(-1), last.beam_index,
                              last.beam_nodes)
        ev = lat.evaluate(r)
        if st is not None:
            st.topology = (key, ev)
        return ev
    shown = shown_lattice(rig, lat, panel)  # the program's own filter, then the panels'
    return jobs.call(lambda: shown.evaluate(r), rig.name, f"the filtered evaluation of region {r}")


def apply_filter(rig, settings: dict, prepared=None) -> str | None:
    """Set the panel's filter ``settings`` and redraw (``prepared``: what a job computed for them,
    see ``refresh``); on error the previous settings and drawing come back and the error is
    returned. Rigs filtered by this one follow."""
    old = {k: tuple(v) if k == "stencil_shape" else v for k, v in ((k, getattr(rig.ple, k)) for k in settings)}
    _set_quietly(rig, **settings)
    err = refresh(rig, force=True, prepared=prepared)
    if err:
        _set_quietly(rig, **old)
        refresh(rig, force=True)
        return err
    refresh_dependents(rig)
    return None


def lil_key(rig, coarse) -> tuple:
    """What a LiL job of ``rig`` by ``coarse`` depends on: if it changed while the job ran, its
    result is not drawn (the filter is evaluated again)."""
    return signature(rig), signature(coarse), _flat(rig.matrix_world.inverted() @ coarse.matrix_world)


def shown_lattice(rig, lat=None, panel=None):
    """The rig's lattice as its panels show it: the program's filter and the Filters panel's
    and-ed, then the Body panel's grading, body and cleanup, so that drawing, tessellation and
    export evaluate the same kept set."""
    lat = lattice_of(rig) if lat is None else lat
    shown = lat.with_filter(filtered(rig, lat) if panel is None else panel)
    return body_panel.fill(rig, shown, region_of(rig, lat))


# ----- reading user moves ---------------------------------------------------------------------
def _flat(m) -> tuple:
    return tuple(float(x) for row in m for x in row)


def _moved(obj, expected: dict, key) -> bool:
    old = expected.get(key)
    return old is not None and max(abs(a - b) for a, b in zip(_flat(obj.matrix_basis), old)) > MOVE_TOL


def user_edits(rig, st: RigState) -> list:
    """Edits for frames and template nodes the user moved since the last drawing (§6.2.2)."""
    lat = st.lattice
    if lat is None:
        return []
    p = parts(rig)
    out = []
    for key in FRAME_NAMES:
        obj = p.get(key)
        if obj is None or not _moved(obj, st.expected, key):
            continue
        m = np.array(obj.matrix_basis)
        scale = max(1.0, float(np.abs(m[:3, 3]).max()))  # numbers keep the precision the frame carries
        if key == "G":
            sim = precision.frame_similarity(cage.placement_from_frame(m, lat.placement), scale)
            out.append(snippets.SetPlacement(sim))
            continue
        axis_n = "uvw".index(key)
        cum = cage.shows_cumulative(lat, key, rig.ple.cumulative[axis_n])
        sim = precision.frame_similarity(cage.direction_from_frame(lat, key, m, cum), scale)
        out.append(snippets.SetDirection(key, None, sim, cum))
    corners = becots_corners(lat)
    if corners and any(p.get(("corner", c)) is not None and _moved(p[("corner", c)], st.expected, ("corner", c))
                       for c in "ABCD"):
        moved = [tuple(p[("corner", c)].matrix_basis.translation) for c in "ABCD"]
        scale = max(1.0, float(np.abs(moved).max()))
        out.append(snippets.SetBecots(tuple(precision.frame_point(c, scale) for c in moved), tuple(lat.becots.counts)))
    for n in range(len(lat.nodes)):
        obj = p.get(("node", n))
        if obj is None or not _moved(obj, st.expected, ("node", n)):
            continue
        loc, _rot, scale = obj.matrix_basis.decompose()
        s = np.array(scale)
        if np.abs(s - s.mean()).max() > 1e-4 * abs(s.mean()) or s.mean() <= 0:
            raise PleError(f"template node {n}: scale it uniformly (the scale is the ball's radius)")
        node = lat.nodes[n]
        loc = precision.frame_point(loc, max(1.0, float(np.abs(np.array(loc)).max())))
        center = tuple(loc) if np.abs(np.array(loc) - node.center).max() > MOVE_TOL else None
        moved_radius = abs(s.mean() - node.radius) > MOVE_TOL * max(1.0, node.radius)
        radius = precision.frame_number(s.mean()) if moved_radius else None
        if center is not None or radius is not None:
            out.append(snippets.MoveNode(n, center, radius))
    return out


# ----- drawing --------------------------------------------------------------------------------
def signature(rig, _seen=()) -> tuple:
    """Everything the drawing depends on; for a LiL filter that includes the coarse rig's
    own signature and its placement (so the fine rig follows its coarse rig)."""
    p = rig.ple
    text = p.text.as_string() if p.text is not None else None
    coarse = None
    if p.filter_kind == "LIL" and is_rig(p.coarse) and p.coarse != rig and uid(p.coarse) not in _seen:
        coarse = (uid(p.coarse), _flat(rig.matrix_world.inverted() @ p.coarse.matrix_world),
                  signature(p.coarse, (*_seen, uid(rig))))
    return (text, tuple(sorted((k, repr(v)) for k, v in params_of(rig).items())), p.edits, tuple(p.region_min),
            tuple(p.region_max), tuple(p.cumulative), p.cage_interior, p.filter_kind, coarse,
            tuple(p.stencil_shape), p.stencil_bits, p.show_template, p.source_kind, body_panel.signature(rig))


def refresh(rig, force: bool = False, prepared=None) -> str | None:
    """Read user moves, re-evaluate and redraw if anything changed; returns an error or None.
    ``prepared``: (lattice, evaluation) a job computed for the rig as it is now, drawn instead
    of evaluating again unless the user moved something since.

    Errors (bad program, degenerate frame) leave the program text, the edits and the last
    good drawing untouched and are shown as the rig's status."""
    global _busy
    if _busy:
        return None
    claim(rig)
    st = state_of(rig)
    _busy = True
    try:
        try:
            if st.lattice is None and st.expected:  # moves made before the program could run
                st.lattice = lattice_of(rig, st)
            new = user_edits(rig, st)
            if not new and not force and signature(rig) == st.signature and st.lattice is not None:
                if rig.ple.status:  # e.g. a degenerate frame was put back: nothing is wrong now
                    rig.ple.status = ""
                return None
            if prepared is not None and not new:
                lat, ev = prepared
            else:
                lat = lattice_of(rig, st, new)  # new edits are kept only if the lattice they give is valid
                ev = evaluate_region(rig, lat, st)
        except PleError as exc:
            if rig.ple.status != str(exc):
                notify(rig, str(exc))
            rig.ple.status = str(exc)
            return str(exc)
        add_edits(rig, new)
        st.lattice = lat
        if not {"G", "u", "v", "w", "cage", "region"} <= set(parts(rig)):
            build_parts(rig, lat)  # a copy (Shift+D) or a rig whose parts were deleted
        draw_rig(rig, lat, ev, st)
        for hook in AFTER_DRAW:  # e.g. the CLG preview (clg_rig.py)
            hook(rig, lat)
        st.signature = signature(rig)
        st.cumulative = tuple(rig.ple.cumulative)
        st.region = (tuple(rig.ple.region_min), tuple(rig.ple.region_max))
        if rig.ple.status:
            rig.ple.status = ""
        return None
    finally:
        _busy = False


def draw_rig(rig, lat, ev, st: RigState) -> None:
    p = parts(rig)
    if tuple(rig.ple.counts) != lat.counts:
        rig.ple.counts = lat.counts
    if "region" in p:
        draw.region_mesh(p["region"].data, ev)
        draw.set_detail(p["region"], 0 if ev is None else len(ev.center) + len(ev.beam_nodes))
    if "cage" in p:
        draw.cage_curve(p["cage"].data, cage.cage_curves(lat, interior=rig.ple.cage_interior))
    frames = {"G": lat.placement.matrix}
    for n, axis in enumerate("uvw"):
        frames[axis] = cage.direction_frame(lat, axis, rig.ple.cumulative[n])
    for key, m in frames.items():
        if key in p:
            st.expected[key] = draw.set_matrix(p[key], m)
    sync_nodes(rig, lat, p, st)
    sync_corners(rig, lat, p, st)


def sync_nodes(rig, lat, p: dict, st: RigState) -> None:
    """One sphere empty per template node (child of G): location = centre, scale = radius."""
    want = len(lat.nodes) if rig.ple.show_template else 0
    stale = [obj for key, obj in p.items() if isinstance(key, tuple) and key[0] == "node" and key[1] >= want]
    if stale:
        layer = bpy.context.view_layer
        if layer is not None and layer.objects.active in stale:
            layer.objects.active = rig  # the active node goes: the rig becomes active, not nothing
        bpy.data.batch_remove(stale)
    for key in [k for k in st.expected if isinstance(k, tuple) and k[0] == "node" and k[1] >= want]:
        del st.expected[key]
    for n in range(want):
        obj = p.get(("node", n))
        if obj is None:
            obj = new_part(rig, f"{rig.name}.N{n}", None, "NODE", parent=p.get("G"))
            obj.empty_display_type = "SPHERE"
            obj.empty_display_size = 1.0
            obj.ple.node_index = n
        node = lat.nodes[n]
        m = np.diag([node.radius, node.radius, node.radius, 1.0])
        m[:3, 3] = node.center
        st.expected[("node", n)] = draw.set_matrix(obj, m)


def becots_corners(lat) -> list:
    """Corners A, B, C, D (points) of the lattice's BeCOTS slab; [] if it has none or its
    field is not given by plain corners (branches, closed or stacked slabs: not editable)."""
    becots = getattr(lat, "becots", None)
    if becots is None:
        return []
    data = becots.to_ir()
    if set(data) != {"corners", "counts"}:
        return []
    return [np.asarray(c, dtype=float) for c in data["corners"]]


def sync_corners(rig, lat, p: dict, st: RigState) -> None:
    """Corner empties A, B, C, D of a BeCOTS slab (children of G); moving one re-makes the
    slab from the four corners (``set_becots``, thesis §4.2)."""
    corners = becots_corners(lat)
    stale = [obj for key, obj in p.items() if isinstance(key, tuple) and key[0] == "corner" and not corners]
    if stale:
        bpy.data.batch_remove(stale)
        for label in "ABCD":
            st.expected.pop(("corner", label), None)
    for label, c in zip("ABCD", corners):
        obj = p.get(("corner", label))
        if obj is None:
            obj = new_part(rig, f"{rig.name}.{label}", None, "CORNER", parent=p.get("G"))
            obj.empty_display_type = "CUBE"
            obj.empty_display_size = 0.5 * handle_size(lat)
            obj.ple.frame = label
        m = np.eye(4)
        m[:3, 3] = c
        st.expected[("corner", label)] = draw.set_matrix(obj, m)


# ----- building a rig -------------------------------------------------------------------------
def new_part(rig, name: str, data, role: str, parent=None):
    obj = bpy.data.objects.new(name, data)
    for coll in rig.users_collection:
        coll.objects.link(obj)
    obj.parent = parent if parent is not None else rig
    obj.matrix_parent_inverse = Matrix.Identity(4)
    obj.ple.role = role
    obj.ple.rig = rig
    return obj


def set_params(rig, inputs) -> None:
    """Program inputs (``runtime.Param``) as custom properties with slider ranges (``Range(lo, hi)``)."""
    for prm in inputs:
        key = PARAM_PREFIX + prm.name
        if key not in rig:
            rig[key] = prm.default
        if isinstance(prm.default, (int, float)) and not isinstance(prm.default, bool):
            ui = rig.id_properties_ui(key)
            opts = {"description": f"program input {prm.name} of lattice()"}
            if prm.range is not None:
                kind = type(prm.default)  # an int input gets int limits
                lo, hi = kind(prm.range.lo), kind(prm.range.hi)
                opts.update(min=lo, max=hi, soft_min=lo, soft_max=hi)
            ui.update(**opts)


def handle_size(lat) -> float:
    """Display size of frame handles, readable on the whole lattice: half the mean U, V, W step
    (their translation at the cage point), at least 3 % of the cage's extent, at most two steps,
    and at least twice the mean ball radius."""
    steps = [np.linalg.norm(cage.direction_frame(lat, a)[:3, 3] - cage.base_frame(lat)[:3, 3]) for a in "uvw"]
    step = float(np.mean([x for x in steps if x > 0])) if any(x > 0 for x in steps) else 1.0
    pts = np.concatenate(cage.cage_curves(lat, interior=0))
    extent = float(np.ptp(pts, axis=0).max()) if len(pts) else step
    size = min(max(0.5 * step, 0.03 * extent), 2.0 * step)
    return max(size, 2.0 * float(lat.template_radii.mean()), 1e-3)


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
           clg: bool = False):
    """Build a rig for ``text`` (a Text datablock) at ``location`` (default: the 3D cursor);
    raises PleError before creating anything if the program or IR is bad or the region is
    beyond the work budget. With ``clg``, ``text`` holds a CLG and the rig edits its pattern."""
    st = RigState()
    probe = bpy.data.objects.new("~ple probe", None)  # evaluate before building anything
    try:
        probe.ple.text, probe.ple.source_kind = text, source_kind
        probe.ple_clg.active = clg
        _trusted.add(uid(probe))
        base = base_lattice(probe, st)
        inputs = st.inputs
        clamped = tuple(min(r, c) for r, c in zip(region, base.counts))
        work.check(work.estimate(base, f"0:{clamped[0]},0:{clamped[1]},0:{clamped[2]}"),
                    max_bytes=prefs.max_bytes(), what="drawing the region")
    finally:
        _trusted.discard(uid(probe))
        bpy.data.objects.remove(probe)
    coll = bpy.data.collections.new(f"PLE {name}")
    context.scene.collection.children.link(coll)
    rig = bpy.data.objects.new(name, None)
    coll.objects.link(rig)
    rig.location = context.scene.cursor.location if location is None else location
    rig.empty_display_type = "PLAIN_AXES"
    rig.empty_display_size = handle_size(base)
    rig.ple.role = "RIG"
    rig.ple.text, rig.ple.source_kind = text, source_kind
    rig.ple_clg.active = clg
    rig.ple.region_max = clamped
    trust(rig)
    claim(rig)
    if inputs is not None:
        set_params(rig, inputs)
    build_parts(rig, base)
    _state[uid(rig)] = st
    err = refresh(rig, force=True)
    if err:
        raise PleError(err)
    return rig


def remove(rig) -> None:
    """Delete a rig's objects and its own datablocks (meshes, curves), keeping the program text."""
    objs = [rig, *rig.children_recursive]
    data = [o.data for o in objs if o.data is not None and o.data.users <= 1]
    colls = [c for c in rig.users_collection if c.name.startswith("PLE ")]
    _state.pop(rig.ple.uid, None)
    _owner.pop(rig.ple.uid, None)
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
        _state.pop(rig.ple.uid, None)
    orphans += gone
    if orphans:
        data = [o.data for o in orphans if o.data is not None and o.data.users <= 1]
        bpy.data.batch_remove(orphans + data)
    return len(orphans)


PART_ROLES = ("FRAME", "NODE", "CORNER", "CAGE", "REGION", "CLG")


def claim(rig) -> None:
    """Register the rig's stable id; a rig holding another object's id is a copy (Shift+D):
    it gets its own id, its own program text (a copy), the original's trust, and parts of its own."""
    key = uid(rig)
    owner = _owner.get(key)
    if owner is None or owner == rig.session_uid:
        _owner[key] = rig.session_uid
        return
    if not any(o.session_uid == owner and o.ple.uid == key for o in all_rigs()):
        _owner[key] = rig.session_uid  # the holder is gone (deleted, or a new session)
        return
    make_independent(rig, was_trusted=key in _trusted)


def make_independent(rig, was_trusted: bool) -> None:
    rig.ple.uid = uuid.uuid4().hex
    _owner[rig.ple.uid] = rig.session_uid
    if was_trusted:
        _trusted.add(rig.ple.uid)
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
    _state.pop(copy.ple.uid, None)
    err = refresh(copy, force=True)
    if err:
        raise PleError(err)
    return copy


# ----- reports from handlers ---------------------------------------------------------------------
_pending_reports: list[str] = []


def notify(rig, message: str) -> None:
    """A problem met outside an operator (live editing): besides the panel's status line it goes
    to the Info editor, through the ``ple.report`` operator run from a timer right after the
    handler (handlers cannot report; in background mode timers never fire: ``flush_reports``)."""
    _pending_reports.append(f"{rig.name}: {message}")
    del _pending_reports[:-50]  # background sessions never flush: keep only the latest
    if not bpy.app.background and not bpy.app.timers.is_registered(flush_reports):
        bpy.app.timers.register(flush_reports, first_interval=0.0)


def flush_reports():
    while _pending_reports:
        msg = _pending_reports.pop(0)
        try:
            bpy.ops.ple.report(message=msg)
        except RuntimeError:
            print(f"PLE: {msg}")
    return None


# ----- update callbacks and handlers ----------------------------------------------------------
def on_settings_changed(rig) -> None:
    """A setting of the panel changed; a region beyond the work budget (or otherwise bad) is
    refused: the region settings go back to the last drawn ones, the error is the status."""
    if _busy or not is_rig(rig):
        return
    st = state_of(rig)
    err = refresh(rig)
    if err and st.region and (tuple(rig.ple.region_min), tuple(rig.ple.region_max)) != st.region:
        _set_quietly(rig, region_min=st.region[0], region_max=st.region[1])
        refresh(rig, force=True)
        rig.ple.status = err
    refresh_dependents(rig)


def _set_quietly(rig, **settings) -> None:
    global _busy
    was, _busy = _busy, True
    try:
        for k, v in settings.items():
            setattr(rig.ple, k, v)
    finally:
        _busy = was


def on_cumulative_changed(rig) -> None:
    """The Cumulative toggle only changes what a frame shows; a stored frame edit is re-expressed
    in the shown form (incremental <-> cumulative), so a later count change keeps what the
    user sees (the step, or the span from group 0 to the last group)."""
    if _busy or not is_rig(rig):
        return
    st = state_of(rig)
    lat = st.lattice
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
            _set_quietly(rig, edits=snippets.edits_to_json(edits))
        except PleError as exc:
            rig.ple.status = str(exc)
    on_settings_changed(rig)


def on_counts_changed(rig) -> None:
    """The counts slider: a count-only set_u/v/w edit per changed direction. Counts the core
    refuses (absurd, or a region beyond the work budget) are not stored: the slider goes back
    and the reason is the status."""
    if _busy or not is_rig(rig):
        return
    st = state_of(rig)
    if st.lattice is None:
        return
    old_counts = st.lattice.counts
    edits = [snippets.SetDirection(axis, int(c)) for axis, c, old in zip("uvw", rig.ple.counts, old_counts)
             if int(c) != old]
    try:
        lat = lattice_of(rig, st, edits)
        lat.validate()
        r = region_of(rig, lat)
        if r is not None:
            work.check(work.estimate(lat, r), max_bytes=prefs.max_bytes(), what=f"drawing region {r}")
        add_edits(rig, edits)
    except PleError as exc:
        _set_quietly(rig, counts=old_counts)
        rig.ple.status = f"counts {tuple(int(c) for c in rig.ple.counts)} kept: {exc}"
        return
    refresh(rig)
    refresh_dependents(rig)


def dependents(rig, _seen=()) -> list:
    """Rigs whose LiL filter uses ``rig`` as coarse lattice, directly or through a cascade."""
    out = []
    for other in all_rigs():
        if (other != rig and other.ple.filter_kind == "LIL" and other.ple.coarse == rig
                and uid(other) not in _seen):
            out.append(other)
            out.extend(dependents(other, (*_seen, uid(rig), uid(other))))
    return out


def refresh_dependents(rig) -> None:
    for dep in dependents(rig):
        refresh(dep)


def rigs_in_updates(depsgraph) -> list:
    """Rigs touched by an update, then the rigs whose LiL filter depends on them."""
    found = {}
    for u in depsgraph.updates:
        obj = u.id.original if isinstance(u.id, bpy.types.Object) else None
        if obj is None or obj.ple.role not in ("RIG", "FRAME", "NODE", "CORNER"):
            continue
        rig = rig_of(obj)
        if rig is not None:
            found[rig.as_pointer()] = rig
    for rig in list(found.values()):
        for dep in dependents(rig):
            found.pop(dep.as_pointer(), None)
            found[dep.as_pointer()] = dep  # after its coarse rig
    return list(found.values())


def all_rigs() -> list:
    return [o for o in bpy.data.objects if o.ple.role == "RIG"]


_object_count = [0]


def check_removed(scene) -> None:
    """After objects left the scene: remove the parts of rigs whose lattice object is gone."""
    n = len(scene.objects)
    if n < _object_count[0]:
        remove_orphans()
        n = len(scene.objects)
    _object_count[0] = n
