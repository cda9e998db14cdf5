"""The Blender side of ``ple bench addon`` (issue 39): one rig, one drawn region, timed in a fresh
headless bpy 5.0.1 process (its peak memory is this region's alone).

Run by ``ple.bench.addon`` as ``python benchmarks/addon_redraw.py ROOT COUNT REGION EDITS``:
``ROOT`` holds the ``core/`` and ``ple_addon/`` to measure (this checkout, or today's code at the
baseline revision), ``COUNT`` the cubic lattice's count along each axis, ``REGION`` the drawn
groups along each axis. Prints one JSON line after ``@@``.

Every step is what a user's frame change costs: set a frame (or the counts), then two
``view_layer.update()`` calls, the first running the add-on's depsgraph handler (read the move,
evaluate, write the region), the second Blender's evaluation of what it wrote (the geometry-nodes
drawing). *settle*: the region drawn in full once the moves pause, where a live move drew less.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import sys
import tempfile
import time


def main() -> None:
    root, count, region, edits = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp()
    sys.path[:0] = [root, os.path.join(root, "core")]
    import bpy

    import ple_addon
    from ple_addon.rig import model, sync

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ple_addon.register()
    bpy.ops.ple.lattice_add(source="PRESET", preset="cubic", region=(3, 3, 3))
    rig = bpy.context.active_object
    rig.ple.counts = (count, count, count)
    update = bpy.context.view_layer.update
    update()

    def step(change) -> float:
        t0 = time.perf_counter()
        change()
        update()
        update()
        return time.perf_counter() - t0

    def region_set():
        rig.ple.region_max = (region, region, region)

    first = step(region_set)
    if rig.ple.status:
        raise SystemExit(f"the region was not drawn: {rig.ple.status}")
    p = model.parts(rig)
    me = p["region"].data
    balls, beams = len(me.vertices), len(me.edges)  # drawn in full (the core's counts: tests/addon)

    def moves(obj, n):
        out = []
        for e in range(n):
            def move(e=e):
                obj.location = (obj.location[0] + (0.01 if e % 2 == 0 else -0.01), obj.location[1], obj.location[2])
            out.append(step(move))
        return out

    drag_u = moves(p["u"], edits)
    drawn = len(me.vertices) + len(me.edges)  # balls and beams a live move draws
    settle = step(sync.settle) if hasattr(sync, "settle") else None
    drag_g = moves(p["G"], edits)
    counts = []
    for e in range(max(2, edits // 2)):
        def recount(e=e):
            rig.ple.counts = (count + (1 if e % 2 == 0 else 0), count, count)
        counts.append(step(recount))
    result = {"balls": balls, "beams": beams, "first_draw_s": first,
              "drag_u_ms": 1e3 * statistics.median(drag_u), "drag_u_max_ms": 1e3 * max(drag_u),
              "drag_g_ms": 1e3 * statistics.median(drag_g), "drag_g_max_ms": 1e3 * max(drag_g),
              "counts_ms": 1e3 * statistics.median(counts),
              "settle_ms": None if settle is None else 1e3 * settle,
              "drawn_while_dragging": drawn,
              "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9}
    print("@@" + json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
