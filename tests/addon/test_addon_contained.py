"""Contained work in the add-on (issues 15 and 20), headless bpy 5.0.1 from the installed zip: lattice
programs and long core work (LiL, tessellation) run in a child process (``ple.program.runner``), so
an endless loop, one long core call or a memory bomb is reported within its limit while Blender
stays alive and the rig unchanged; a LiL job cancelled (Esc) or over its time limit changes nothing.

The cases run in the test run's one Blender worker (``conftest.py``) with the helpers of
``test_addon_live``; truth comes from the core installed in the environment.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
import test_addon_live as live

CASES = ["program_loop", "program_memory_bomb", "program_exits", "programs_still_run", "lil_job",
         "lil_job_cancel", "lil_job_time_limit", "tessellate_job_time_limit"]


@pytest.mark.parametrize("case", CASES)
def test_addon_contained(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
def prefs():
    return live.bpy.context.preferences.addons["bl_ext.user_default.ple"].preferences


def no_child_left() -> bool:
    """True when this process has no child process (a job's child was stopped and collected)."""
    try:
        os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def set_program(rig, good: str, inside: str = "", top: str = "") -> None:
    """The rig's program ``good`` with lines put at the start of lattice() and at the top level."""
    assert "    lat = Lattice()" in good
    rig.ple.text.from_string(top + good.replace("    lat = Lattice()", inside + "    lat = Lattice()", 1))


def timed(fn, *args, **kw):
    t0 = time.monotonic()
    out = fn(*args, **kw)
    print(f"TIMING {time.monotonic() - t0:.2f} s (loaded machine)")
    return out


LOOPS = {  # (lines in lattice(), lines at the top level)
    "a loop in lattice()": ("    while True:\n        pass\n", ""),
    "a loop at the top level": ("", "while True:\n    pass\n"),
    # one C call: no Python line runs inside it, so no trace-based limit could stop it
    "one long builtin call": ("    s = sum(range(10**12))\n", ""),
}


def case_program_loop():
    """Endless programs (in lattice(), at the top level, one long builtin call) are stopped by the
    time limit with a report; the rig keeps its drawing and Blender goes on working."""
    bpy = live.bpy
    rig = live.new_rig("cubic", region=(2, 2, 2))
    co0 = live.region_arrays(rig)[0]
    good = rig.ple.text.as_string()
    prefs().program_seconds = 1.0
    for label, (inside, top) in LOOPS.items():
        set_program(rig, good, inside, top)
        msg = timed(live.fails, bpy.ops.ple.program_run, "ran longer than 1 s")
        assert rig.ple.text.name in msg and "preferences" in msg, (label, msg)
        assert "ran longer than 1 s" in rig.ple.status, label
        assert np.array_equal(live.region_arrays(rig)[0], co0), label
        assert no_child_left(), label
    before = len(bpy.data.objects)
    text = bpy.data.texts.new("loop.py")
    text.from_string("def lattice():\n" + LOOPS["one long builtin call"][0] + "    return Lattice()\n")
    live.fails(bpy.ops.ple.lattice_add, "ran longer than 1 s", source="TEXT", text="loop.py")
    assert len(bpy.data.objects) == before  # nothing half-built
    set_program(rig, good)
    assert bpy.ops.ple.program_run() == {"FINISHED"} and rig.ple.status == ""
    assert np.array_equal(live.region_arrays(rig)[0], co0)
    other = live.new_rig("octet", region=(2, 2, 2))  # Blender responsive: the next rig is drawn
    live.assert_region_is(other, live.core.load_lattice("octet"), "0:2,0:2,0:2")


def case_program_memory_bomb():
    """A program allocating 20 GiB (Python or numpy) is reported as out of memory within the memory
    limit of the preferences; Blender survives and the rig is unchanged."""
    bpy = live.bpy
    rig = live.new_rig("cubic", region=(2, 2, 2))
    co0 = live.region_arrays(rig)[0]
    good = rig.ple.text.as_string()
    prefs().memory_gb = 1.0
    for inside, top in (("    b = bytearray(20 * 2**30)\n", ""),
                        ("    a = np.ones(20 * 2**27)\n", "import numpy as np\n"),
                        ("    keep = []\n    while True:\n        keep.append(bytearray(2**26))\n", "")):
        set_program(rig, good, inside, top)
        msg = timed(live.fails, bpy.ops.ple.program_run, "ran out of memory")
        assert "limit 1 GiB" in msg and "preferences" in msg, msg
        assert np.array_equal(live.region_arrays(rig)[0], co0) and no_child_left()
    assert live.new_rig("cubic", region=(2, 2, 2)).ple.status == ""  # alive and working


def case_program_exits():
    """sys.exit, os._exit, a BaseException and a crash of a program end the child, not Blender."""
    bpy = live.bpy
    rig = live.new_rig("cubic", region=(2, 2, 2))
    co0 = live.region_arrays(rig)[0]
    good = rig.ple.text.as_string()
    for inside, needle in (("    import sys\n    sys.exit(3)\n", "called sys.exit(3)"),
                           ("    import os\n    os._exit(0)\n", "called os._exit(0)"),
                           ("    raise KeyboardInterrupt\n", "raised KeyboardInterrupt"),
                           ("    import os, signal\n    os.kill(os.getpid(), signal.SIGSEGV)\n",
                            "crashed with SIGSEGV")):
        set_program(rig, good, inside)
        msg = live.fails(bpy.ops.ple.program_run, needle)
        assert rig.ple.text.name in msg
        assert np.array_equal(live.region_arrays(rig)[0], co0) and no_child_left()


def case_programs_still_run():
    """Normal programs run contained give the same lattice and inputs (sliders with their ranges)
    as the core in this process; Apply (which runs the program) still round-trips."""
    bpy, core = live.bpy, live.core
    rig = live.new_rig("fig6_3", region=(3, 3, 2))
    prog = core.program.runtime.compile_program(core.program.presets.preset_path("fig6_3").read_text())
    for prm in prog.parameters():
        assert rig[f"ple:{prm.name}"] == prm.default
        if prm.range is not None:
            ui = rig.id_properties_ui(f"ple:{prm.name}").as_dict()
            assert np.isclose(ui["min"], prm.range.lo) and np.isclose(ui["max"], prm.range.hi)
    live.assert_region_is(rig, core.load_lattice("fig6_3"), "0:3,0:3,0:2")
    fu = live.part(rig, "u")
    fu.location = (fu.location[0] + 0.2, fu.location[1], fu.location[2])
    live.update()
    gui = live.ple_ext.rig.model.lattice_of(rig)
    assert bpy.ops.ple.program_apply() == {"FINISHED"} and rig.ple.edits == "[]"
    assert core.program.snippets.lattices_close(live.rerun(rig), gui, 1e-9)
    assert no_child_left()


def _lil_pair():
    fine = live.new_rig("cubic", region=(10, 10, 10))
    coarse = live.new_rig("fig6_3")
    coarse.location = (2, 2, 0)
    live.update()
    return fine, coarse


def _want_lil(at=(2, 2, 0)):
    core = live.core
    c = core.load_lattice("fig6_3")
    c.set_placement(core.Translation(core.Vec(*at)) @ c.placement)
    return core.filters.lil(core.load_lattice("cubic"), c).evaluate("0:10,0:10,0:10")


def case_lil_job():
    """The LiL filter runs as a job: progress fractions rise box by box, the rig changes only at
    the end, the result (the core's LiL in this process) and a message reach the panel."""
    bpy = live.bpy
    fine, coarse = _lil_pair()
    co0 = live.region_arrays(fine)[0]
    op = live.stepped_op(bpy.types.PLE_OT_lil_filter, coarse=coarse.name)
    steps = op.steps(bpy.context, fine)
    fracs = []
    for frac in steps:
        fracs.append(frac)
        if frac < 1.0:  # while the job runs nothing is applied
            assert fine.ple.filter_kind == "NONE" and np.array_equal(live.region_arrays(fine)[0], co0)
    assert fracs[0] == 0.0 and fracs[-1] == 1.0 and fracs == sorted(fracs), fracs
    assert fine.ple.filter_kind == "LIL" and fine.ple.coarse == coarse
    want = _want_lil()
    co, _, ed = live.region_arrays(fine)
    assert np.allclose(co, want.center, atol=1e-5) and np.array_equal(ed, want.beam_nodes)
    assert f"{len(want.center)} of 1000 balls" in op.result
    assert bpy.ops.ple.lil_filter(rig=fine.name, coarse=coarse.name) == {"FINISHED"}  # the operator
    assert "kept" in fine.ple.message and no_child_left()


def case_lil_job_cancel():
    """Esc during a LiL job (closing its steps) stops the child: the rig is unchanged."""
    bpy = live.bpy
    fine, coarse = _lil_pair()
    co0, _, ed0 = live.region_arrays(fine)
    edits = fine.ple.edits
    op = live.stepped_op(bpy.types.PLE_OT_lil_filter, coarse=coarse.name)
    steps = op.steps(bpy.context, fine)
    assert next(steps) == 0.0
    assert next(steps) < 1.0  # the child is running
    assert not no_child_left()
    steps.close()  # what Esc does in the modal run
    assert no_child_left()
    co, _, ed = live.region_arrays(fine)
    assert fine.ple.filter_kind == "NONE" and fine.ple.edits == edits and fine.ple.status == ""
    assert np.array_equal(co, co0) and np.array_equal(ed, ed0)
    coarse.location = (3, 2.5, 0)  # and live editing goes on unfiltered
    live.update()
    assert np.array_equal(live.region_arrays(fine)[0], co0)


def case_lil_job_time_limit():
    """A LiL job beyond the job time limit is stopped with a report: nothing applied."""
    bpy = live.bpy
    fine, coarse = _lil_pair()
    co0 = live.region_arrays(fine)[0]
    prefs().job_seconds = 0.001
    msg = live.fails(bpy.ops.ple.lil_filter, "ran longer than 0.001 s", rig=fine.name, coarse=coarse.name)
    assert "LiL filter" in msg and "preferences" in msg
    assert fine.ple.filter_kind == "NONE" and np.array_equal(live.region_arrays(fine)[0], co0)
    assert "ran longer" in fine.ple.status and no_child_left()
    prefs().job_seconds = 600.0
    assert bpy.ops.ple.lil_filter(rig=fine.name, coarse=coarse.name) == {"FINISHED"}
    assert len(live.region_arrays(fine)[0]) == len(_want_lil().center)


def case_tessellate_job_time_limit():
    """A tessellation whose one box outlasts the job time limit is stopped (its child killed):
    no mesh, no object; the next tessellation works."""
    bpy = live.bpy
    rig = live.new_rig("cubic", region=(4, 4, 4))
    meshes, objects = len(bpy.data.meshes), len(bpy.data.objects)
    prefs().job_seconds = 0.2
    msg = timed(live.fails, bpy.ops.ple.tessellate, "ran longer than 0.2 s", style="REFINED")
    assert "refined tessellation" in msg and no_child_left()
    assert (len(bpy.data.meshes), len(bpy.data.objects)) == (meshes, objects)
    prefs().job_seconds = 600.0
    rig.ple.region_max = (2, 2, 2)
    assert bpy.ops.ple.tessellate(style="CHOCC") == {"FINISHED"}
    assert len(bpy.data.objects) == objects + 1 and "triangles" in rig.ple.message
