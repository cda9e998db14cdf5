"""A rig read as a core lattice (Blender state -> ``ple.Lattice``): its objects, its program and
inputs, its GUI edits, its drawn region and its filters.

A rig is a collection holding the lattice object (an empty, ``obj.ple.role == "RIG"``, whose
program lives in a Text datablock and whose inputs are custom properties ``ple:<name>``), the
placement frame G, the frames U, V, W, the template nodes, the BeCOTS corners, the cage and the
region. Everything geometric is the core's; this module only reads Blender state into core calls.
"""

from __future__ import annotations

import hashlib
import json
import uuid
from typing import NamedTuple

import bpy
import numpy as np

from .. import jobs, prefs
from ..corelink import PleError, Similarity, cage, core, ir, irfile, snippets, work
from ..session import SESSION, RigState
from . import hooks

PARAM_PREFIX = "ple:"
PART_ROLES = ("FRAME", "NODE", "CORNER", "CAGE", "REGION", "CLG")


def flat(m) -> tuple:
    """A matrix (4x4 Blender or numpy) as a flat tuple of floats."""
    return tuple(float(x) for row in m for x in row)


def uid(rig) -> str:
    """The rig's stable id (kept through renames and file saves; a duplicate gets its own)."""
    if not rig.ple.uid:
        rig.ple.uid = uuid.uuid4().hex
    return rig.ple.uid


def state_of(rig) -> RigState:
    return SESSION.state(uid(rig))


def is_rig(obj) -> bool:
    return obj is not None and obj.ple.role == "RIG"


def rig_of(obj):
    """The rig an object belongs to (itself if it is one), or None."""
    if obj is None:
        return None
    if obj.ple.role == "RIG":
        return obj
    return obj.ple.rig if obj.ple.rig is not None and obj.ple.rig.ple.role == "RIG" else None


def all_rigs() -> list:
    return [o for o in bpy.data.objects if o.ple.role == "RIG"]


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


# ----- program, trust, edits ----------------------------------------------------------------------
def params_of(rig) -> dict:
    return {k[len(PARAM_PREFIX):]: (v.to_dict() if hasattr(v, "to_dict") else v)
            for k, v in rig.items() if k.startswith(PARAM_PREFIX)}


def clamp_inputs(rig) -> str:
    """Set the inputs a script put beyond their slider's Range (Blender limits only the slider,
    not ``rig["ple:x"] = v``) to the nearest end of it; what was clamped, or ""."""
    said = []
    for key in [k for k in rig.keys() if k.startswith(PARAM_PREFIX)]:
        value = rig[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        ui = rig.id_properties_ui(key).as_dict()
        lo, hi = ui.get("min"), ui.get("max")
        if lo is None or hi is None or lo <= value <= hi:
            continue
        rig[key] = lo if value < lo else hi
        said.append(f"{key[len(PARAM_PREFIX):]} {value:g} clamped to {rig[key]:g} (its Range {lo:g}–{hi:g})")
    return f"input {'; '.join(said)}" if said else ""


def params_key(params: dict) -> tuple:
    return tuple(sorted((k, repr(v)) for k, v in params.items()))


def trusted(rig) -> bool:
    """Programs run only if Blender trusts scripts or the user ran this one explicitly (SPEC §9)."""
    return (rig.ple.source_kind == "IR" or uid(rig) in SESSION.trusted
            or bpy.context.preferences.filepaths.use_scripts_auto_execute)


def trust(rig) -> None:
    SESSION.trusted.add(uid(rig))


def programs() -> dict:
    """Rig uid -> fingerprint of its program (source kind and text) for the rigs of the open file:
    what trust kept across files is checked against (``Session.restore_trust``)."""
    out = {}
    for rig in all_rigs():
        if rig.ple.text is not None:
            data = f"{rig.ple.source_kind}\0{rig.ple.text.as_string()}".encode()
            out[uid(rig)] = hashlib.sha256(data).hexdigest()
    return out


def read_json(source: str, name: str):
    """The data of a JSON text (an IR file); PleError naming the line of a syntax error."""
    try:
        return json.loads(source)
    except json.JSONDecodeError as exc:
        raise PleError(f"{name}: malformed JSON at line {exc.lineno}: {exc.msg}") from None


def base_lattice(rig, st: RigState):
    """The lattice the program (or IR) gives, before GUI edits; cached per text and inputs."""
    text = rig.ple.text
    if text is None:
        raise PleError(f"{rig.name}: the program text block is missing")
    source = text.as_string()
    st.clamped = clamp_inputs(rig) or st.clamped  # shown by the next drawing (``sync.refresh``)
    params = params_of(rig)
    key = (rig.ple.source_kind, source, params_key(params), rig.ple.folder)
    if key == st.program_key:
        return st.base
    if rig.ple.source_kind == "PROGRAM" and not trusted(rig):
        raise PleError(f"{text.name}: not run because Blender does not trust scripts "
                       "(enable Auto Run Python Scripts, or press Run Program; frame moves are "
                       "kept until then)")
    found = hooks.first("loaders", rig, source, params, text.name)  # e.g. a CLG rig: the CLG's pattern
    if found is not None:
        inputs, base = found
    elif rig.ple.source_kind == "IR":
        loader = irfile.body_loader(bpy.path.abspath(rig.ple.folder)) if rig.ple.folder else None
        base, inputs = ir.lattice_from_ir(read_json(source, text.name), loader), None
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


# ----- region and filters ---------------------------------------------------------------------------
def region_of(rig, lat):
    """The drawn index box, clamped to the lattice; None if empty."""
    lo = [min(a, c) for a, c in zip(rig.ple.region_min, lat.counts)]
    hi = [min(b, c) for b, c in zip(rig.ple.region_max, lat.counts)]
    if any(a >= b for a, b in zip(lo, hi)):
        return None
    return lat.region(f"{lo[0]}:{hi[0]},{lo[1]}:{hi[1]},{lo[2]}:{hi[2]}")


def check_budget(lat, region, what: str | None = None) -> None:
    """Refuse drawing ``region`` of ``lat`` beyond the work budget of the preferences (PleError)."""
    work.check(work.estimate(lat, region), max_bytes=prefs.max_bytes(), what=what or f"drawing region {region}")


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
    if kind == "STENCIL":
        shape = tuple(rig.ple.stencil_shape)
        bits = rig.ple.stencil_bits.strip()
        n = int(np.prod(shape))
        if len(bits) != n or set(bits) - {"0", "1"}:
            raise PleError(f"stencil: expected {n} characters 0/1 for shape {shape}, got {bits!r}")
        return core("filters").Stencil(np.array([c == "1" for c in bits]).reshape(shape))
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


def shown_lattice(rig, lat=None, panel=None):
    """The rig's lattice as its panels show it: the program's filter and the Filters panel's
    and-ed, then what features add (a body's grading, fill and cleanup), so that drawing,
    tessellation and export evaluate the same kept set."""
    lat = lattice_of(rig) if lat is None else lat
    shown = lat.with_filter(filtered(rig, lat) if panel is None else panel)
    region = region_of(rig, lat)
    for fn in hooks.each("shown"):
        shown = fn(rig, shown, region)
    return shown


def moves_rigidly(rig, lat) -> bool:
    """Does a move of G move the drawing as a whole? Yes unless something that decides what is
    kept or how thick it is reads placed coordinates: a filter (the program's, the panel's, a
    feature's), a radius field, a group map."""
    return (lat.filter is None and rig.ple.filter_kind == "NONE" and lat.radius_field is None
            and lat.group_map is None and not any(fn(rig) for fn in hooks.each("filtering")))


def unplaced(lat):
    """``lat`` without its placement G: what a rigidly moved drawing holds (its object is placed by G)."""
    out = lat.copy()
    out.set_placement(Similarity())
    return out


class Drawn(NamedTuple):
    """What a drawing holds of an evaluation: node indices (N, 4), centres, radii and the beams'
    end rows as int32 (Blender's edge vertices); no beam indices (a drawing needs none)."""

    node_index: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    beam_nodes: np.ndarray

    @classmethod
    def of(cls, ev) -> Drawn:
        return cls(ev.node_index, ev.center, ev.radius, ev.beam_nodes.astype(np.int32))


def evaluate_region(rig, lat, st: RigState | None = None):
    """The drawn region (``Drawn``, None if empty) through the program's and the panel's filters,
    and the matrix of the region object that places it: G when the drawing moves rigidly
    (``moves_rigidly``; the region is then evaluated before G, so that a move of G only moves
    the object), otherwise the identity. Unfiltered, a move of a frame changes only ball centres
    and radii: the node and beam rows of the last drawing are reused (``Lattice.region_balls``)."""
    r = region_of(rig, lat)
    if r is None:
        return None, np.eye(4)
    check_budget(lat, r)
    if moves_rigidly(rig, lat):
        local = unplaced(lat)
        key = (str(r), len(lat.nodes), tuple((b.n1, b.n2, b.di, b.dj, b.dk) for b in lat.beams))
        centers, radii = local.region_balls(r)
        if st is not None and st.topology and st.topology[0] == key:
            nodes, beams = st.topology[1]
        else:
            nodes, beams = r.node_index(len(lat.nodes)), local.region_beam_nodes(r, np.int32)
            if st is not None:
                st.topology = (key, (nodes, beams))
        return Drawn(nodes, centers.reshape(-1, 3), radii.reshape(-1), beams), lat.placement.matrix
    shown = shown_lattice(rig, lat)  # the program's own filter, then the panels'
    ev = jobs.call(lambda: shown.evaluate(r), rig.name, f"the filtered evaluation of region {r}")
    return Drawn.of(ev), np.eye(4)


# ----- what a drawing depends on --------------------------------------------------------------------
def signature(rig, _seen=()) -> tuple:
    """Everything the drawing depends on; for a LiL filter that includes the coarse rig's
    own signature and its placement (so the fine rig follows its coarse rig)."""
    p = rig.ple
    text = p.text.as_string() if p.text is not None else None
    coarse = None
    if p.filter_kind == "LIL" and is_rig(p.coarse) and p.coarse != rig and uid(p.coarse) not in _seen:
        coarse = (uid(p.coarse), flat(rig.matrix_world.inverted() @ p.coarse.matrix_world),
                  signature(p.coarse, (*_seen, uid(rig))))
    return (text, params_key(params_of(rig)), p.edits, tuple(p.region_min), tuple(p.region_max),
            tuple(p.cumulative), p.cage_interior, p.filter_kind, coarse, tuple(p.stencil_shape), p.stencil_bits,
            p.show_template, p.source_kind, tuple(fn(rig) for fn in hooks.each("signatures")))


def lil_key(rig, coarse) -> tuple:
    """What a LiL job of ``rig`` by ``coarse`` depends on: if it changed while the job ran, its
    result is not drawn (the filter is evaluated again)."""
    return signature(rig), signature(coarse), flat(rig.matrix_world.inverted() @ coarse.matrix_world)


def dependents(rig, _seen=()) -> list:
    """Rigs whose LiL filter uses ``rig`` as coarse lattice, directly or through a cascade."""
    out = []
    for other in all_rigs():
        if (other != rig and other.ple.filter_kind == "LIL" and other.ple.coarse == rig
                and uid(other) not in _seen):
            out.append(other)
            out.extend(dependents(other, (*_seen, uid(rig), uid(other))))
    return out


def register() -> None:
    pass


def unregister() -> None:
    pass
