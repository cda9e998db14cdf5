"""Live-editing redraw time of the Blender extension (SPEC §8: <= 50 ms for a 10^3-group region).

Run: ``.venv/bin/python benchmarks/addon_redraw.py`` (headless bpy 5.0.1); prints JSON.
For each lattice, a 10x10x10-group region is drawn; the U frame is moved ``--edits`` times and
each edit is timed end to end: ``view_layer.update()`` = depsgraph_update_post handler (read
frames -> GUI edit -> core evaluation -> region mesh + cage curve writes) + depsgraph
evaluation of the geometry-nodes balls-and-beams drawing. ``python_redraw`` is the handler's
own share. Baseline (same run): the naive redraw that builds the full ball-and-beam preview
mesh with the core (``ple.preview``) and writes it into a Blender mesh.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--edits", type=int, default=30)
    parser.add_argument("--lattices", default="cubic,fig6_3,octet")
    parser.add_argument("--out", help="also write the JSON to this file")
    args = parser.parse_args()
    os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp()
    sys.path.insert(0, str(ROOT))
    import bpy

    import ple_addon

    bpy.ops.wm.read_factory_settings(use_empty=True)
    ple_addon.register()
    rows = [measure(bpy, name, args.edits) for name in args.lattices.split(",")]
    text = json.dumps({"benchmark": "addon_redraw", "edits": args.edits, "machine": {
        "cpus": os.cpu_count(), "python": platform.python_version(), "blender": bpy.app.version_string,
        "load_average": os.getloadavg()[0]}, "target_ms": 50, "rows": rows}, indent=1)
    if args.out:
        Path(args.out).write_text(text + "\n")
    print(text)


def measure(bpy, name: str, edits: int) -> dict:
    from ple.meshing.preview import balls_beams_mesh

    from ple_addon import draw
    from ple_addon.rig import model, sync

    bpy.ops.ple.lattice_add(source="PRESET", preset=name, region=(10, 10, 10))
    r = bpy.context.active_object
    if min(r.ple.counts) < 10:
        r.ple.counts = tuple(max(10, c) for c in r.ple.counts)
    r.ple.region_max = (10, 10, 10)  # exactly 10^3 node-groups
    bpy.context.view_layer.update()
    frame = model.parts(r)["u"]
    start = frame.location.copy()
    total, handler = [], []
    orig_refresh = sync.refresh

    def timed_refresh(obj, force=False):
        t0 = time.perf_counter()
        out = orig_refresh(obj, force)
        handler.append(time.perf_counter() - t0)
        return out

    sync.refresh = timed_refresh
    try:
        for n in range(edits):
            frame.location = (start[0] + 0.01 * (n % 7 + 1), start[1], start[2])
            t0 = time.perf_counter()
            bpy.context.view_layer.update()
            total.append(time.perf_counter() - t0)
    finally:
        sync.refresh = orig_refresh
    region = model.parts(r)["region"]
    evaluated = region.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    lat = model.lattice_of(r)
    box = model.region_of(r, lat)
    ev = model.evaluate_region(r, lat)
    t_eval = min(_time(lambda: lat.evaluate(box)) for _ in range(5))
    t_write = min(_time(lambda: draw.region_mesh(region.data, ev)) for _ in range(5))

    def naive():
        e = lat.evaluate(box)
        m = balls_beams_mesh(e.center, e.radius, e.beam_nodes)
        me = bpy.data.meshes.new("naive")
        me.vertices.add(len(m.vertices))
        me.loops.add(3 * len(m.faces))
        me.polygons.add(len(m.faces))
        me.attributes["position"].data.foreach_set("vector", np.asarray(m.vertices, np.float32).ravel())
        me.attributes[".corner_vert"].data.foreach_set("value", np.asarray(m.faces, np.int32).ravel())
        me.polygons.foreach_set("loop_start", np.arange(0, 3 * len(m.faces), 3, dtype=np.int32))
        me.update(calc_edges=True)
        bpy.data.meshes.remove(me)

    t_naive = min(_time(naive) for _ in range(3))
    return {
        "lattice": name, "region_groups": int(np.prod(box.shape)),
        "balls": len(ev.center), "beams": len(ev.beam_nodes),
        "drawn_vertices_after_geometry_nodes": len(evaluated.vertices),
        "edit_to_redraw_ms_median": 1e3 * statistics.median(total), "edit_to_redraw_ms_max": 1e3 * max(total),
        "python_redraw_ms_median": 1e3 * statistics.median(handler),
        "core_evaluate_ms": 1e3 * t_eval, "region_write_ms": 1e3 * t_write,
        "baseline_full_mesh_redraw_ms": 1e3 * t_naive,
        "speedup_vs_baseline": t_naive / statistics.median(total),
    }


def _time(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
