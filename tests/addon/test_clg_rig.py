"""The CLG rig of the add-on (issue 16), installed from the built zip into headless bpy 5.0.1.

The cases run in the test run's one Blender worker (``conftest.py``). Truth comes from the core
installed in the environment (an independent copy of the vendored one): Monte Carlo volumes over its
PMC, its meshes and voxels of the edited pattern, and volumes and edge counts computed here from the
Blender mesh data.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import test_addon as base

CASES = ["add_sources", "mesh_preview_volume", "corner_edit_follows", "frame_edit_steady", "voxel_and_slice_preview",
         "operators_write_files", "apply_to_clg_file", "duplicate_remove", "errors"]

PROGRAM = '''"""A CLG program: hollow beams of a cubic pattern."""


def clg(hollow: Range(0.3, 0.8) = 0.5):
    lat = Lattice()
    n = lat.add_node(Pt(0, 0, 0), 0.2, "n")
    lat.add_beam(n, n, 1, 0, 0)
    lat.add_beam(n, n, 0, 1, 0)
    lat.set_u(3, Translation(Vec(1, 0, 0)))
    lat.set_v(2, Translation(Vec(0, 1, 0)))
    chunks = {"tubes": Union(HollowBeam((0, 0, 0, "n"), (1, 0, 0, "n"), (1, 1), hollow),
                             HollowBeam((0, 0, 0, "n"), (0, 1, 0, "n"), (1, 1), hollow))}
    return CLG(lat, chunks, Chunk("tubes"))
'''


@pytest.mark.parametrize("case", CASES)
def test_clg_rig_case(run_case, case):
    run_case(__file__, case)


# ----- bpy side (runs in the Blender worker) --------------------------------------------------------
def new_clg(preset="plate", **kw):
    assert base.bpy.ops.ple.clg_add(source="PRESET", preset=preset, **kw) == {"FINISHED"}
    return base.bpy.context.active_object


def preview_data(rig):
    """Vertices (n, 3) and polygons (list of index arrays) of the rig's preview mesh."""
    me = base.part(rig, "clg").data
    co = np.zeros(len(me.vertices) * 3, np.float32)
    me.attributes["position"].data.foreach_get("vector", co)
    start = np.zeros(len(me.polygons), np.int32)
    total = np.zeros(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    corner = np.zeros(len(me.loops), np.int32)
    me.attributes[".corner_vert"].data.foreach_get("value", corner)
    return co.reshape(-1, 3).astype(float), [corner[s:s + t] for s, t in zip(start, total)]


def enclosed_volume(co, polys):
    """Signed volume by the divergence theorem over a fan of every polygon (computed here)."""
    tri = np.array([(p[0], p[k], p[k + 1]) for p in polys for k in range(1, len(p) - 1)])
    a, b, c = co[tri[:, 0]], co[tri[:, 1]], co[tri[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def directed_edges(polys) -> dict:
    edges = {}
    for p in polys:
        for a, b in zip(p, np.roll(p, -1)):
            edges[(int(a), int(b))] = edges.get((int(a), int(b)), 0) + 1
    return edges


def closed(polys) -> bool:
    """Every edge used once in each direction: a watertight, consistently oriented 2-manifold."""
    edges = directed_edges(polys)
    return all(n == 1 and edges.get((b, a)) == 1 for (a, b), n in edges.items())


def balanced(polys) -> bool:
    """Every edge used as often in each direction: closed and oriented (voxels touching along an
    edge make it used twice each way)."""
    edges = directed_edges(polys)
    return all(edges.get((b, a)) == n for (a, b), n in edges.items())


def cm(name):
    """A module of the environment's core (not the add-on's vendored copy)."""
    import importlib

    return importlib.import_module(f"ple.{name}")


def monte_carlo_volume(clg, region, n=400_000, seed=0):
    """Volume of the region's solid by the core's PMC at random points of its box, and its 3σ error."""
    comp = cm("clg.query").compiled(clg, region)
    rng = np.random.default_rng(seed)
    p = comp.lo + rng.random((n, 3)) * (comp.hi - comp.lo)
    frac = comp.pmc(p).mean()
    box = float(np.prod(comp.hi - comp.lo))
    return frac * box, 3 * np.sqrt(frac * (1 - frac) / n) * box


def core_clg(name):
    return cm("program.clg_sources").load_clg(name)


def case_add_sources():
    bpy = base.bpy
    rig = new_clg("plate")
    assert rig.ple_clg.active and rig.ple.source_kind == "IR"
    clg = core_clg("plate")
    region = f"0:3,0:3,0:{clg.pattern.counts[2]}"
    base.assert_region_is(rig, clg.pattern, region)  # the rig's lattice is the CLG's pattern
    co, polys = preview_data(rig)
    assert len(polys) > 100 and closed(polys)
    # a program file with an input: the slider is a custom property, changing it re-runs clg()
    path = Path("tubes.py")
    path.write_text(PROGRAM)
    assert bpy.ops.ple.clg_add(source="FILE", filepath=str(path.resolve())) == {"FINISHED"}
    prog = bpy.context.active_object
    assert prog.ple.source_kind == "PROGRAM" and "ple:hollow" in prog.keys()
    v_half = enclosed_volume(*preview_data(prog))
    prog["ple:hollow"] = 0.7
    prog.update_tag()
    base.update()
    v_thin = enclosed_volume(*preview_data(prog))
    assert v_thin < v_half  # larger hollow, thinner tubes
    # a ple-clg/1 text block
    txt = bpy.data.texts.new("shelled.json")
    txt.from_string(cm("program.clg_sources").resolve_clg("shelled").read_text())
    assert bpy.ops.ple.clg_add(source="TEXT", text=txt.name) == {"FINISHED"}
    shelled = bpy.context.active_object
    assert shelled.ple_clg.active and shelled.ple.source_kind == "IR"
    # the panel draws (chunks, solid, buttons) without errors
    seen = []
    panel = base.ple_ext.features.clg.PLE_PT_clg
    assert panel.poll(bpy.context)
    panel.draw(type("P", (), {"layout": base.CheckedLayout(seen)})(), bpy.context)
    for name in ("ple.clg_preview", "ple.clg_voxelize", "ple.clg_slice", "ple.clg_export", "preview", "chunk"):
        assert name in seen, seen


def case_mesh_preview_volume():
    rig = new_clg("plate", region=(3, 2, 1))
    clg = core_clg("plate")
    region = clg.pattern.region("0:3,0:2,0:1")
    co, polys = preview_data(rig)
    assert closed(polys)
    vol = enclosed_volume(co, polys)
    mc, err = monte_carlo_volume(clg, region)
    assert abs(vol - mc) <= err + 0.01 * mc, (vol, mc, err)
    # the preview holds only the region's copies: the whole plate has more volume
    whole, _ = monte_carlo_volume(clg, None, 200_000)
    assert whole > 2 * vol


def case_corner_edit_follows():
    """Drag BeCOTS corner C: the preview is the core's mesh of the CLG on the moved slab."""
    rig = new_clg("plate", region=(2, 2, 1))
    clg = core_clg("plate")
    p = base.ple_ext.rig.model.parts(rig)
    p[("corner", "C")].location = (4.6, 4.2, 1.5)
    base.update()
    assert rig.ple.status == "" and rig.ple_clg.status == "", (rig.ple.status, rig.ple_clg.status)
    moved = [tuple(base.matrix(p[("corner", c)])[:3, 3]) for c in "ABCD"]
    lat = clg.pattern.copy()
    lat.set_becots(*moved, counts=tuple(clg.pattern.becots.counts))
    want = cm("meshing.clg").mesh_clg(clg.with_pattern(lat), rig.ple_clg.segments, lat.region("0:2,0:2,0:1"))
    co, polys = preview_data(rig)
    assert len(co) == len(want.vertices)
    assert np.allclose(np.sort(co, axis=0), np.sort(want.vertices, axis=0), atol=1e-5)
    assert abs(enclosed_volume(co, polys) - want.volume) <= 1e-4 * want.volume
    old = cm("meshing.clg").mesh_clg(clg, rig.ple_clg.segments, clg.pattern.region("0:2,0:2,0:1"))
    assert abs(old.volume - want.volume) > 1e-3 * old.volume  # the edit changed the solid


def case_frame_edit_steady():
    """Move the U frame of a steady CLG (shelled): the preview's volume follows the edited pattern."""
    rig = new_clg("shelled", region=(2, 2, 2))
    rig.ple_clg.segments = 48  # a thin shell: the difference of two meshes, within 1 % at 48 segments
    p = base.ple_ext.rig.model.parts(rig)
    u = p["u"]
    m = base.matrix(u)
    m[:3, 3] += np.array([0.3, 0.0, 0.0])  # a longer step along U: longer beams
    u.matrix_basis = base.bpy_matrix(m)
    base.update()
    assert rig.ple.status == "" and rig.ple_clg.status == "", (rig.ple.status, rig.ple_clg.status)
    vendored = base.ple_ext.corelink.core("model.ir")
    lat = cm("model.ir").lattice_from_dict(vendored.lattice_to_dict(base.ple_ext.rig.model.lattice_of(rig)))
    clg = core_clg("shelled")
    assert not np.allclose(lat.U.matrix, clg.pattern.U.matrix)
    co, polys = preview_data(rig)
    assert closed(polys)
    mc, err = monte_carlo_volume(clg.with_pattern(lat), lat.region("0:2,0:2,0:2"))
    vol = enclosed_volume(co, polys)
    assert abs(vol - mc) <= err + 0.01 * mc, (vol, mc, err)
    # the template node's radius edits the pattern too (sphere empty scale = radius)
    node = p[("node", 0)]
    node.scale = tuple(1.2 * x for x in node.scale)
    base.update()
    assert enclosed_volume(*preview_data(rig)) > vol * 1.05


def case_voxel_and_slice_preview():
    rig = new_clg("shelled", region=(2, 2, 1))
    s = rig.ple_clg
    s.voxels = 24
    s.preview = "VOXELS"
    clg = core_clg("shelled")
    region = clg.pattern.region("0:2,0:2,0:1")
    comp = cm("clg.query").compiled(clg, region)
    shape = base.ple_ext.features.clg.grid_shape(comp.lo, comp.hi, 24)
    assert max(shape) == 24
    # independent of the add-on's voxels: PMC at the voxel centres computed here
    axes = [comp.lo[a] + (np.arange(shape[a]) + 0.5) * (comp.hi[a] - comp.lo[a]) / shape[a] for a in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    vox = comp.pmc(centres).reshape(shape)
    co, polys = preview_data(rig)
    assert all(len(q) == 4 for q in polys) and balanced(polys)
    cell = np.prod((comp.hi - comp.lo) / np.array(shape))
    assert abs(enclosed_volume(co, polys) - vox.sum() * cell) <= 1e-4 * vox.sum() * cell
    assert np.all(co >= comp.lo - 1e-5) and np.all(co <= comp.hi + 1e-5)
    s.preview = "SLICE"
    s.slice_height = 0.5
    co, polys = preview_data(rig)
    assert len(polys) and balanced(polys)
    assert np.ptp(co[:, 2]) == pytest.approx((comp.hi[2] - comp.lo[2]) / shape[2], rel=1e-4)
    s.preview = "NONE"
    assert base.part(rig, "clg").hide_viewport


def case_operators_write_files():
    bpy = base.bpy
    new_clg("shelled", region=(2, 2, 1))
    clg = core_clg("shelled")
    region = clg.pattern.region("0:2,0:2,0:1")
    comp = cm("clg.query").compiled(clg, region)
    assert bpy.ops.ple.clg_voxelize(filepath=str(Path("v.npy").resolve()), grid=(10, 12, 6)) == {"FINISHED"}
    vox = np.load("v.npy")
    axes = [comp.lo[a] + (np.arange(n) + 0.5) * (comp.hi[a] - comp.lo[a]) / n for a, n in enumerate((10, 12, 6))]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    assert vox.shape == (10, 12, 6) and np.array_equal(vox, comp.pmc(centres).reshape(vox.shape))
    assert bpy.ops.ple.clg_slice(directory=str(Path("slices").resolve()), layer=0.1, pixel=0.05) == {"FINISHED"}
    man = json.loads(Path("slices/manifest.json").read_text())
    assert man["layers"] == len(list(Path("slices").glob("layer_*.png"))) == int(np.ceil(
        (comp.hi[2] - comp.lo[2]) / 0.1 - 1e-9))
    assert bpy.ops.ple.clg_export(filepath=str(Path("part.stl").resolve()), segments=32) == {"FINISHED"}
    import trimesh

    mesh = trimesh.load("part.stl")
    assert mesh.is_watertight
    mc, err = monte_carlo_volume(clg, region)
    assert abs(mesh.volume - mc) <= err + 0.01 * mc, (mesh.volume, mc, err)
    whole = str(Path("whole.stl").resolve())
    assert bpy.ops.ple.clg_export(filepath=whole, segments=16, whole=True) == {"FINISHED"}
    assert trimesh.load(whole).volume > 1.5 * mesh.volume


def case_apply_to_clg_file():
    """Apply to Program writes the dragged corners into the ple-clg/1 text's pattern; the CLG read
    back from the text is the edited one (same preview); a clg() program is refused, text kept."""
    bpy = base.bpy
    rig = new_clg("plate", region=(2, 2, 1))
    p = base.ple_ext.rig.model.parts(rig)
    p[("corner", "C")].location = (4.6, 4.2, 1.5)
    base.update()
    before = preview_data(rig)[0].copy()
    assert bpy.ops.ple.program_apply() == {"FINISHED"}
    assert base.ple_ext.rig.model.edits_of(rig) == []
    data = json.loads(rig.ple.text.as_string())
    moved = [list(base.matrix(p[("corner", c)])[:3, 3]) for c in "ABCD"]
    assert np.allclose(data["pattern"]["becots"]["corners"], moved, atol=1e-6)
    clg = cm("clg.ir").clg_from_dict(data)  # the environment's core reads the rewritten file
    assert set(clg.chunks) == set(core_clg("plate").chunks)
    assert np.allclose(np.sort(preview_data(rig)[0], axis=0), np.sort(before, axis=0), atol=1e-5)
    path = Path("tubes.py")
    path.write_text(PROGRAM)
    assert bpy.ops.ple.clg_add(source="FILE", filepath=str(path.resolve())) == {"FINISHED"}
    prog = bpy.context.active_object
    u = base.ple_ext.rig.model.parts(prog)["u"]
    u.location = (u.location[0] + 0.2, u.location[1], u.location[2])
    base.update()
    base.fails(bpy.ops.ple.program_apply, "Copy Snippet")
    assert prog.ple.text.as_string() == PROGRAM


def case_duplicate_remove():
    """A copy of a CLG rig is a CLG rig with its own preview; removing a rig takes its preview along."""
    bpy = base.bpy
    rig = new_clg("connectors", region=(2, 2, 1))
    assert bpy.ops.ple.duplicate() == {"FINISHED"}
    copy = bpy.context.active_object
    assert copy != rig and copy.ple_clg.active
    a, b = base.part(rig, "clg"), base.part(copy, "clg")
    assert a != b and a.data != b.data
    va, vb = preview_data(rig)[0], preview_data(copy)[0]
    shift = np.array(copy.matrix_world)[:3, 3] - np.array(rig.matrix_world)[:3, 3]
    assert np.allclose(va, vb) and np.linalg.norm(shift) > 0  # same solid, in the copy's own frame
    name = b.name
    assert bpy.ops.ple.remove() == {"FINISHED"}
    assert bpy.data.objects.get(name) is None and base.part(rig, "clg").name == a.name


def case_errors():
    bpy = base.bpy
    bad = json.loads(cm("program.clg_sources").resolve_clg("shelled").read_text())
    bad["solid"] = {"difference": ["X", "nope"]}
    txt = bpy.data.texts.new("bad.json")
    txt.from_string(json.dumps(bad))
    n_objects = len(bpy.data.objects)
    base.fails(bpy.ops.ple.clg_add, "unknown chunk 'nope'", source="TEXT", text=txt.name)
    assert len(bpy.data.objects) == n_objects  # nothing half-made
    rig = new_clg("shelled", region=(1, 1, 1))
    good = preview_data(rig)[0].copy()
    rig.ple_clg.chunk = "nope"  # an unknown chunk: the status says so, the last preview stays
    assert "unknown chunk 'nope'" in rig.ple_clg.status, rig.ple_clg.status
    assert np.array_equal(preview_data(rig)[0], good)
    base.fails(bpy.ops.ple.clg_preview, "unknown chunk")
    rig.ple_clg.chunk = rig.ple_clg.chunk.replace("nope", "")
    assert rig.ple_clg.status == ""
    base.fails(bpy.ops.ple.clg_export, "choose a .stl", filepath="x.txt")
    assert "choose a .stl" in rig.ple.status  # the panel's status line too
    base.fails(bpy.ops.ple.clg_voxelize, "choose a .npy", filepath="x.txt")
    base.fails(bpy.ops.ple.clg_slice, "pixels per layer exceed", directory=str(Path("s").resolve()),
               layer=0.5, pixel=1e-5)
    # a plain lattice rig is not a CLG rig
    base.new_rig("cubic")
    base.fails(bpy.ops.ple.clg_preview, "select a PLE CLG object")
