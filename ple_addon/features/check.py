"""The Check panel: ``ple check``'s design rules (clean, thinnest beam, smallest gap, slenderness,
dangling beams, isolated balls, components) and the mass properties of the drawn region or the
whole lattice, as its panel filter keeps it. The core computes the report
(``measure.check.check_report``) and its text (``rule_lines``); an offender is shown by moving the
drawn region onto it (``offender_region``), so the region drawing displays it.
"""

from __future__ import annotations

import json

import bpy
from bpy.props import EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

from ..corelink import PleError, core
from ..ops.base import RigOperator, RigPanel
from ..rig import model

check = core("measure.check")
SHOWN_OFFENDERS = 3  # offenders listed (with a Show button) per failing rule


class PLE_PG_check(bpy.types.PropertyGroup):  # noqa: N801 - Blender naming
    scope: EnumProperty(name="Check", items=[("REGION", "Drawn Region", "The drawn index region"),
                                             ("WHOLE", "Whole Lattice", "Every group of the lattice")],
                        default="REGION")
    min_feature: FloatProperty(name="Min Feature", min=0.0, default=0.0, precision=4,
                               description="Smallest printable feature (thinnest beam diameter, smallest gap); "
                                           "0: no limit")
    max_slenderness: FloatProperty(name="Max Slenderness", min=0.0, default=0.0,
                                   description="Largest beam length / diameter; 0: no limit")
    report: StringProperty(name="Report", description="The last check's report (JSON)")


def report_of(obj) -> dict | None:
    """The last check report stored on a lattice object, or None."""
    text = obj.ple_check.report
    return json.loads(text) if text else None


class PLE_OT_check(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Check the design rules and mass properties of the lattice as drawn (ple check)"""

    bl_idname = "ple.check"
    bl_label = "Check Lattice"

    def run(self, context, rig):
        s = rig.ple_check
        lat = model.shown_lattice(rig)  # the panel's filter too: what is drawn is what is checked
        region = None
        if s.scope == "REGION":
            region = model.region_of(rig, lat)
            if region is None:
                raise PleError("the region is empty: set Region from/to inside the repetition counts")
        report = check.check_report(lat, region, s.min_feature or None, s.max_slenderness or None)
        s.report = json.dumps(report)
        failed = [key for key, ok, _, _ in check.rule_lines(report) if not ok]
        if failed:
            self.report({"WARNING"}, f"{len(failed)} rules fail: {', '.join(failed)}")
        else:
            self.report({"INFO"}, f"every rule holds ({report['nodes']} balls, {report['beams']} beams)")
        return {"FINISHED"}


class PLE_OT_check_show(RigOperator, bpy.types.Operator):  # noqa: N801 - Blender naming
    """Move the drawn region onto an offender of the last check"""

    bl_idname = "ple.check_show"
    bl_label = "Show Offender"

    rule: StringProperty(name="Rule", description="Rule of the last check report")
    index: IntProperty(name="Offender", min=0, description="Position in the rule's list of worst offenders")

    def run(self, context, rig):
        report = report_of(rig)
        if report is None:
            raise PleError("no check report yet: run Check Lattice first")
        worst = report["rules"].get(self.rule, {}).get("worst", [])
        if self.index >= len(worst):
            raise PleError(f"rule {self.rule!r} has no offender {self.index}")
        r = check.offender_region(model.shown_lattice(rig), worst[self.index])
        rig.ple.region_min, rig.ple.region_max = (r.i0, r.j0, r.k0), (r.i1, r.j1, r.k1)
        return self.refreshed(rig)


class PLE_PT_check(RigPanel, bpy.types.Panel):  # noqa: N801 - Blender naming
    bl_label = "Check"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        rig = self.rig(context)
        s, layout = rig.ple_check, self.layout
        layout.prop(s, "scope", expand=True)
        row = layout.row(align=True)
        row.prop(s, "min_feature")
        row.prop(s, "max_slenderness")
        layout.operator("ple.check", icon="CHECKMARK")
        report = report_of(rig)
        if report is None:
            return
        kept = " kept" if report["filtered"] else ""
        layout.label(text=f"{report['region']}: {report['nodes']:,} balls, {report['beams']:,} beams{kept}")
        for key, ok, text, worst in check.rule_lines(report, SHOWN_OFFENDERS):
            layout.label(text=text, icon="CHECKMARK" if ok else "ERROR")
            for n, line in enumerate(worst):
                row = layout.row()
                row.label(text=line)
                op = row.operator("ple.check_show", text="", icon="VIEWZOOM")
                op.rule, op.index = key, n
        mass = report.get("mass")
        if mass:
            box = layout.column(align=True)
            box.label(text=f"area {mass['area']:.6g}   volume {mass['volume']:.6g}")
            if mass["centroid"] is not None:
                box.label(text="centroid (" + ", ".join(f"{x:.4g}" for x in mass["centroid"]) + ")")
                box.label(text="inertia diag (" + ", ".join(f"{mass['inertia'][i][i]:.4g}" for i in range(3)) + ")")


CLASSES = (PLE_PG_check, PLE_OT_check, PLE_OT_check_show, PLE_PT_check)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Object.ple_check = PointerProperty(type=PLE_PG_check)


def unregister():
    del bpy.types.Object.ple_check
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
