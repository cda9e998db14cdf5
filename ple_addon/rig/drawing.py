"""Writing a rig's drawing: the region (placed by G where it moves rigidly; its hull while a big
region is moved live), the cage, the frames, template nodes and BeCOTS corners (``draw`` writes
the Blender data)."""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from .. import draw
from ..corelink import cage, core
from ..session import RigState
from .model import Drawn, becots_corners, moves_rigidly, parts, unplaced

preview = core("meshing.preview")

# balls + beams a live move redraws in full: geometry nodes instance about 10⁷ elements a second on
# two cores (``ple bench addon``), so a move redraws these in ~30 ms and the handler and cage fit
# beside them in 100 ms; a bigger region shows its hull while it moves
LIVE_ELEMENTS = 300_000
KEPT = object()  # an evaluation not redone: the drawing is kept, only its placement moves


def live_view(ev, st: RigState) -> Drawn:
    """What a live move draws of a region of more than ``LIVE_ELEMENTS``: its hull
    (``preview.hull_rows``), chosen once per topology."""
    nodes = ev.node_index
    if st.hull is None or st.hull[0] is not nodes or st.hull[1] != LIVE_ELEMENTS:
        keep, _beams, ends = preview.hull_rows(nodes, ev.beam_nodes, LIVE_ELEMENTS)
        st.hull = (nodes, LIVE_ELEMENTS, keep, ends.astype(np.int32))
    _, _, keep, ends = st.hull
    return Drawn(nodes[keep], ev.center[keep], ev.radius[keep], ends)


def draw_rig(rig, lat, ev, st: RigState, at=None, live: bool = False) -> bool:
    """Write the drawing: the region (``ev``, placed by the matrix ``at``; ``KEPT``: only moved),
    the cage (in the same coordinates), the frames, template nodes and corners. True when a
    ``live`` move drew only the region's hull (it is drawn in full once the moves pause)."""
    p = parts(rig)
    at = np.eye(4) if at is None else at
    if tuple(rig.ple.counts) != lat.counts:
        rig.ple.counts = lat.counts
    st.rigid = moves_rigidly(rig, lat) and np.array_equal(at, lat.placement.matrix)  # drawn before G
    if "region" in p:
        if ev is not KEPT:
            full = ev is None or len(ev.center) + len(ev.beam_nodes) <= LIVE_ELEMENTS or not live
            shown = ev if full else live_view(ev, st)
            draw.region_mesh(p["region"].data, shown)
            draw.set_detail(p["region"], 0 if shown is None else len(shown.center) + len(shown.beam_nodes))
            st.hull_drawn = not full
        draw.set_matrix(p["region"], at)
    if "cage" in p:
        if ev is not KEPT:
            drawn = lat if np.array_equal(at, np.eye(4)) else unplaced(lat)
            draw.cage_curve(p["cage"].data, cage.cage_curves(drawn, interior=rig.ple.cage_interior))
        draw.set_matrix(p["cage"], at)
    frames = {"G": lat.placement.matrix}
    for n, axis in enumerate("uvw"):
        frames[axis] = cage.direction_frame(lat, axis, rig.ple.cumulative[n])
    for key, m in frames.items():
        if key in p:
            st.expected[key] = draw.set_matrix(p[key], m)
    sync_nodes(rig, lat, p, st)
    sync_corners(rig, lat, p, st)
    return st.hull_drawn and ev is not KEPT


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


def new_part(rig, name: str, data, role: str, parent=None):
    obj = bpy.data.objects.new(name, data)
    for coll in rig.users_collection:
        coll.objects.link(obj)
    obj.parent = parent if parent is not None else rig
    obj.matrix_parent_inverse = Matrix.Identity(4)
    obj.ple.role = role
    obj.ple.rig = rig
    return obj


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


def register() -> None:
    pass


def unregister() -> None:
    pass
