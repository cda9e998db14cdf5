"""The Blender side of ``ple bench tessellate_blender`` (core/ple/bench/tessellate_blender.py): one
Tessellate of a region in headless Blender, the add-on's (``addon``) or the boxes sent to Blender
and welded there (``baseline``); prints its seconds, triangles and peak memory as one ``@@`` JSON
line. Kept out of the core, which never imports bpy.

Run by the bench: ``python benchmarks/tessellate_blender_child.py ROOT PRESET REGION STYLE addon|baseline``.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import tempfile
import time


def main(argv: list[str]) -> None:
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp()  # before bpy: the user's Blender stays as it is
    sys.path.insert(0, argv[0])
    import bpy

    import ple_addon

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ple_addon.register()
    preset, region, style, how = argv[1:5]
    lo, hi = zip(*(map(int, part.split(":")) for part in region.split(",")))
    assert bpy.ops.ple.lattice_add(source="PRESET", preset=preset, region=(1, 1, 1)) == {"FINISHED"}
    rig = bpy.context.active_object
    from ple_addon import prefs

    prefs.DEFAULTS.update(memory_gb=20.0, max_triangles=10**9)  # registered, not enabled: the defaults are the limits
    rig.ple.region_min, rig.ple.region_max = lo, hi
    bpy.context.view_layer.update()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    if how == "addon":
        assert bpy.ops.ple.tessellate(style=style.upper()) == {"FINISHED"}
        me = bpy.data.objects[f"{rig.name}.{style}"].data
    else:  # the earlier path: every box sent to Blender, welded there
        me = _baseline(rig, style)
    seconds = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print("@@" + json.dumps({"seconds": seconds, "triangles": len(me.polygons), "peak_bytes": peak * 1024,
                             "before_bytes": before * 1024}))


def _baseline(rig, style: str):
    from ple_addon import jobs
    from ple_addon.corelink import core
    from ple_addon.draw import mesh_from_arrays
    from ple_addon.rig import model

    pipeline = core("app.pipeline")
    lat = model.shown_lattice(rig)
    p = pipeline.plan(pipeline.MeshRequest(lat, model.region_of(rig, lat), style))
    job = jobs.start(lambda: pipeline.stream(p, {}), rig.name, "baseline", True)
    gen = jobs.follow(job, lambda items: 0.0)
    try:
        while True:
            next(gen)
    except StopIteration as stop:
        chunks, _ = stop.value
    verts, faces = pipeline.weld_chunks(chunks)
    return mesh_from_arrays("baseline", verts, faces)


if __name__ == "__main__":
    main(sys.argv[1:])
