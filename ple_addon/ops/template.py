"""Operators of the template and the filters: template nodes and beam-patterns, the index stencil and
the LiL filter (a job)."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import (
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    IntVectorProperty,
    StringProperty,
)

from .. import jobs
from ..corelink import PleError, snippets
from ..rig import events, model
from .base import BEYOND, PROGRESS_BOXES, RigOperator, SteppedOperator


class PLE_OT_node_add(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a node (ball) to the template node-group N[0,0,0]"""

    bl_idname = "ple.node_add"
    bl_label = "Add Template Node"

    center: FloatVectorProperty(name="Centre", size=3, description="Centre in the placement frame")
    radius: FloatProperty(name="Radius", min=1e-6, default=0.05, description="Ball radius")

    def run(self, context, rig):
        model.add_edits(rig, [snippets.AddNode(tuple(self.center), self.radius)])
        return self.refreshed(rig)


def _selected_nodes(context, rig) -> list[int]:
    sel = [o for o in context.selected_objects if o.ple.role == "NODE" and o.ple.rig == rig]
    act = context.active_object
    sel.sort(key=lambda o: o != act)  # the active node first
    return [o.ple.node_index for o in sel]


class PLE_OT_node_remove(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Remove a template node and every beam-pattern using it"""

    bl_idname = "ple.node_remove"
    bl_label = "Remove Template Node"

    index: IntProperty(name="Node", default=-1, min=-1, description="Template node index (-1: the active node)")

    def run(self, context, rig):
        idx = self.index if self.index >= 0 else next(iter(_selected_nodes(context, rig)), -1)
        if idx < 0:
            raise PleError("select a template node (sphere empty) or give its index")
        lat = model.lattice_of(rig)
        if len(lat.nodes) <= 1:
            raise PleError("the template node-group needs at least one node")
        snippets.apply_to_lattice(lat, [snippets.RemoveNode(idx)])  # validates before recording
        model.add_edits(rig, [snippets.RemoveNode(idx)])
        return self.refreshed(rig)


class PLE_OT_beam_add(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Add a beam-pattern joining node n1 of group (i, j, k) to node n2 of group (i+di, j+dj, k+dk)"""

    bl_idname = "ple.beam_add"
    bl_label = "Add Beam-Pattern"

    n1: IntProperty(name="From node", default=-1, min=-1, description="-1: the active selected node")
    n2: IntProperty(name="To node", default=-1, min=-1, description="-1: the other selected node")
    offset: IntVectorProperty(name="Offset", size=3, default=(1, 0, 0), description="(di, dj, dk)")

    def run(self, context, rig):
        sel = _selected_nodes(context, rig)
        n1 = self.n1 if self.n1 >= 0 else (sel[0] if sel else -1)
        n2 = self.n2 if self.n2 >= 0 else (sel[1] if len(sel) > 1 else n1)
        if n1 < 0:
            raise PleError("pick two template nodes (or one, for a beam to its own copy) or give n1, n2")
        edit = snippets.AddBeam(n1, n2, *self.offset)
        snippets.apply_to_lattice(model.lattice_of(rig), [edit])  # validates before recording
        model.add_edits(rig, [edit])
        return self.refreshed(rig)


class PLE_OT_beam_remove(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Remove beam-pattern number ``index``"""

    bl_idname = "ple.beam_remove"
    bl_label = "Remove Beam-Pattern"

    index: IntProperty(name="Beam-pattern", min=0)

    def run(self, context, rig):
        edit = snippets.RemoveBeam(self.index)
        snippets.apply_to_lattice(model.lattice_of(rig), [edit])
        model.add_edits(rig, [edit])
        return self.refreshed(rig)


class PLE_OT_stencil_filter(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Index stencil filter (thesis §9): keep node-group (i, j, k) where the stencil at
    (i, j, k) modulo its shape is 1"""

    bl_idname = "ple.stencil_filter"
    bl_label = "Stencil Filter"

    shape: IntVectorProperty(name="Shape", size=3, min=1, max=16, default=(2, 2, 2))
    bits: StringProperty(name="Stencil", default="10010110", description="0/1 per cell, (i, j, k) order, k fastest")
    clear: bpy.props.BoolProperty(name="Clear", default=False, description="Remove the rig's filter")

    def run(self, context, rig):
        if self.clear:
            rig.ple.filter_kind = "NONE"
            return self.refreshed(rig)
        n = int(np.prod(tuple(self.shape)))
        if len(self.bits) != n or set(self.bits) - {"0", "1"}:
            raise PleError(f"stencil: expected {n} characters 0/1 for shape {tuple(self.shape)}, got {self.bits!r}")
        return self.set_filter(rig, stencil_shape=tuple(self.shape), stencil_bits=self.bits, filter_kind="STENCIL")


class PLE_OT_lil_filter(SteppedOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Lattice-in-Lattice filter (thesis §9): draw only the nodes of the region whose balls
    interfere with a coarse PLE lattice (a job: progress, Esc cancels, the rig changes only
    when it is complete)"""

    bl_idname = "ple.lil_filter"
    bl_label = "LiL Filter"

    coarse: StringProperty(name="Coarse", description="Coarse PLE lattice object (default: another selected one)")
    beyond_limit: BEYOND

    def steps(self, context, rig):
        self._rig = rig
        coarse = bpy.data.objects.get(self.coarse) if self.coarse else next(
            (o for o in context.selected_objects if model.is_rig(o) and o != rig), None)
        if not model.is_rig(coarse) or coarse == rig:
            raise PleError("LiL filter: give (or select) another PLE lattice object as the coarse lattice")
        lat = model.lattice_of(rig)
        shown = lat.with_filter(model.lil_filter(rig, coarse))
        region = model.region_of(rig, lat)
        if region is None:
            raise PleError("the region is empty: set Region from/to inside the repetition counts")
        if not self.beyond_limit:
            model.check_budget(lat, region, f"LiL filter of region {region}")
        key = model.lil_key(rig, coarse)
        yield 0.0
        size = max(1, region.groups // PROGRESS_BOXES)  # the filter is asked box by box: progress
        job = jobs.start(lambda: shown.evaluate_steps(region, max_groups=size), rig.name,
                         f"the LiL filter of region {region}", self.beyond_limit)
        _, ev = yield from jobs.follow(job, lambda items: 0.95 * (items[-1] if items else 0.0))
        # drawn only if nothing it depends on changed meanwhile (else evaluated again, contained)
        prepared = (lat, ev) if model.lil_key(rig, coarse) == key else None
        err = events.apply_filter(rig, {"coarse": coarse, "filter_kind": "LIL"}, prepared)
        if err:
            raise PleError(err)
        kept, total = len(ev.center), region.groups * len(lat.nodes)
        self.result = f"LiL filter by {coarse.name}: {kept} of {total} balls of region {region} kept"
        yield 1.0




CLASSES = (PLE_OT_node_add, PLE_OT_node_remove, PLE_OT_beam_add, PLE_OT_beam_remove, PLE_OT_stencil_filter,
           PLE_OT_lil_filter)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
