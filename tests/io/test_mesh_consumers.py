"""Meshes as consumers read them: files written in float32 read back watertight and manifold
(trimesh, manifold3d), free of self-intersections (exact test), in the stated unit and axes;
3MF read by lib3mf in strict mode without warnings, beam lattices returned exactly."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
import trimesh
from ple.app.pipeline import MeshRequest, write_mesh
from ple.io.export import export_mesh, prepare, write_beam_lattice_3mf
from ple.io.formats import FORMAT_NAMES, Y_UP
from ple.meshing.selfcheck import count_self_intersections, orient3d, self_intersections
from ple.meshing.tessellate import tessellate
from ple.meshing.weld import edge_manifold, grid_spacing, unique_rows, weld
from ple.program.sources import load_lattice

manifold3d = pytest.importorskip("manifold3d")
lib3mf = pytest.importorskip("lib3mf")

FORMATS = list(FORMAT_NAMES)


def read_back(path) -> trimesh.Trimesh:
    """The file as a consumer sees it: vertices with equal coordinates merged (as slicers do
    with STL; trimesh's own merge would also join points closer than 1e-8, which in glTF's
    metres is 1e-5 mm)."""
    mesh = trimesh.load(path, force="mesh", process=False)
    v = np.asarray(mesh.vertices)
    first, inv, _ = unique_rows(v)  # np.unique(v, axis=0)'s rows, without its slow sort of records
    return trimesh.Trimesh(v[first], inv[np.asarray(mesh.faces)], process=False)


def assert_consumer_clean(mesh: trimesh.Trimesh, volume: float | None = None, rel=1e-4):
    v = np.asarray(mesh.vertices)
    f = np.asarray(mesh.faces)
    assert edge_manifold(f) == {"bad_edges": 0, "oriented": True}
    assert mesh.is_watertight and mesh.is_winding_consistent
    m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=v.astype(np.float32), tri_verts=f.astype(np.uint32)))
    assert m.status() == manifold3d.Error.NoError
    assert m.num_tri() >= len(f) - 8  # manifold3d may drop a few collapsed (zero-area) triangles
    if volume is not None:
        assert m.volume() == pytest.approx(volume, rel=rel)
    return m


# ----- the exact self-intersection test against constructed truth ----------------------

def test_orient3d_exact_on_nearly_coplanar_points():
    a, b, c = np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]), np.array([[0.0, 1, 0]])
    d = np.array([[0.1, 0.1, 0.0]])
    assert orient3d(a, b, c, d)[0] == 0
    assert orient3d(a, b, c, d + [0, 0, 1e-300])[0] == -1  # below: right-hand rule, det sign
    assert orient3d(a, b, c, d - [0, 0, 1e-300])[0] == 1
    # points far from the origin: float64 round-off would decide wrongly without the exact fallback
    big = np.array([[1e8, 1e8, 1e8]])
    assert orient3d(a + big, b + big, c + big, d + big + [0, 0, 2.0**-20])[0] == -1


def test_self_intersections_of_constructed_meshes():
    s = trimesh.creation.icosphere(2)
    assert len(self_intersections(s.vertices, s.faces)) == 0
    apart = trimesh.util.concatenate([s, s.copy().apply_translation([2.5, 0, 0])])
    assert len(self_intersections(apart.vertices, apart.faces)) == 0
    both = trimesh.util.concatenate([s, s.copy().apply_translation([0.5, 0.2, 0.1])])
    pairs = self_intersections(both.vertices, both.faces)
    assert len(pairs) > 0
    assert np.all((pairs[:, 0] < len(s.faces)) & (pairs[:, 1] >= len(s.faces)))  # only across spheres
    # a fold: one vertex pushed through the opposite side of a flat, closed box
    box = trimesh.creation.box()
    v = np.array(box.vertices)
    v[0] = -v[0] * 3  # drag a corner through the box
    assert len(self_intersections(v, box.faces)) > 0


# ----- float32 exports read back ----------------------------------------------------------

@pytest.mark.parametrize("name,region,levels", [
    ("becots_kagome", None, 2),   # edges down to 1e-7 before the collapse
    ("fig6_3", None, 1),          # edges down to 3e-8 before the collapse
    ("cubic", "0:4,0:4,0:4", 2),
])
def test_refined_written_in_float32_reads_back_manifold(tmp_path, name, region, levels):
    lat = load_lattice(name)
    mesh = tessellate(lat, region, "refined", levels)
    v, f, _ = prepare(mesh.vertices, mesh.faces, "stl")
    lengths = np.linalg.norm(v[f[:, [1, 2, 0]]] - v[f], axis=2)
    g = grid_spacing(*lat.bounds(region))
    assert lengths.min() >= g  # what is written: every edge at least one float32 grid step
    if not len(mesh.metadata["ple_unclean"].nodes):  # the fast path alone has nothing to weld
        assert len(f) == len(mesh.faces)
    for fmt in ("stl", "ply", "glb"):
        path = tmp_path / f"m.{fmt}"
        export_mesh(mesh, path)
        back = read_back(path)
        assert abs(len(back.faces) - len(f)) <= 8  # glTF's metre grid may weld a few more
        scale = 1e-3 if fmt == "glb" else 1.0
        assert_consumer_clean(back, mesh.volume * scale**3, rel=1e-5)


# clean; clean with pulled contact circles (short beams); unclean, streamed with local unions
# (the warp's 6 x 4 groups: four boxes and their unions, as its 12 x 8 defaults have, in a tenth of the time)
@pytest.mark.parametrize("name, params", [("becots_kagome", {}), ("fig6_3", {}),
                                          ("rectified_warp", {"nu": 6, "nv": 4})],
                         ids=["becots_kagome", "fig6_3", "rectified_warp"])
def test_streamed_stl_reads_back_manifold(tmp_path, name, params):
    lat = load_lattice(name, params)
    path = tmp_path / "s.stl"
    info = {}
    n = write_mesh(MeshRequest(lat, style="refined", levels=1, max_groups=7), path, info=info)  # many boxes
    assert (len(info["unclean"].nodes) > 0) == (name == "rectified_warp")
    back = read_back(path)
    assert len(back.faces) == n
    assert_consumer_clean(back)


def test_weld_merges_what_float32_would_merge():
    # two triangles of a tetrahedron-like fan with one edge far below float32 spacing at 1e3
    tet = trimesh.creation.icosphere(1)
    v = np.array(tet.vertices) * 1000.0
    f = np.array(tet.faces)
    # split vertex 0 into two copies 1e-9 apart joined by a zero-area sliver pair: collapse restores the sphere
    g = grid_spacing(v.min(axis=0), v.max(axis=0))
    assert g >= np.spacing(np.float32(1000.0))
    out_v, out_f, stats = weld(v + 1e-9, f, g)
    assert np.array_equal(out_v, out_v.astype(np.float32).astype(float))
    assert edge_manifold(out_f)["oriented"]
    assert stats["dropped_faces"] == 0


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_of_a_refined_preset(tmp_path, fmt):
    lat = load_lattice("cubic").with_counts(3, 3, 2)
    mesh = tessellate(lat, None, "refined", 2)
    path = tmp_path / f"m.{fmt}"
    export_mesh(mesh, path)
    back = read_back(path)
    scale = 1e-3 if fmt == "glb" else 1.0
    assert_consumer_clean(back, mesh.volume * scale**3, rel=1e-5)
    assert count_self_intersections(back.vertices, back.faces)["self_intersecting_pairs"] == 0


def test_y_up_and_metres_for_gltf_and_obj(tmp_path):
    lat = load_lattice("cubic").with_counts(3, 2, 1)  # longer along x, then y, shortest along z
    mesh = tessellate(lat, None, "cnt")
    lo, hi = mesh.bounds
    for fmt, scale in (("glb", 1e-3), ("obj", 1.0)):
        path = tmp_path / f"m.{fmt}"
        export_mesh(mesh, path)
        back = trimesh.load(path, force="mesh", process=False)
        # our z becomes their y, our y their -z
        expect = np.sort(np.array([lo, hi]) @ Y_UP.T, axis=0) * scale
        assert np.allclose(back.bounds, expect, rtol=0, atol=1e-6 * scale)  # within the float32 snap grid
    text = (tmp_path / "m.obj").read_text().splitlines()[0]
    assert "unit mm" in text and "Y up" in text


def test_units_are_stated(tmp_path):
    mesh = tessellate(load_lattice("cubic").with_counts(1, 1, 1), None, "cnt")
    export_mesh(mesh, tmp_path / "m.stl")
    assert b"unit mm" in (tmp_path / "m.stl").read_bytes()[:80]
    export_mesh(mesh, tmp_path / "m.ply")
    assert b"comment PLE lattice mesh, unit mm" in (tmp_path / "m.ply").read_bytes()[:300]
    export_mesh(mesh, tmp_path / "c.3mf", unit="cm")
    model = _lib3mf_read(tmp_path / "c.3mf")
    assert model.GetUnit() == lib3mf.ModelUnit.CentiMeter


# ----- self-intersections of the styles -------------------------------------------------

@pytest.mark.parametrize("name,region,levels", [
    ("cubic", "0:3,0:3,0:3", 3), ("bcc", "0:2,0:2,0:2", 3), ("warped", "0:2,0:2,0:2", 2),
])
def test_refined_has_no_self_intersections(name, region, levels):
    mesh = tessellate(load_lattice(name), region, "refined", levels)
    assert count_self_intersections(mesh.vertices, mesh.faces)["self_intersecting_pairs"] == 0


def test_cnt_has_no_self_intersections():
    mesh = tessellate(load_lattice("octet"), "0:2,0:2,0:2", "cnt")
    assert len(self_intersections(mesh.vertices, mesh.faces)) == 0


# ----- lib3mf -----------------------------------------------------------------------------

def _lib3mf_read(path):
    wrapper = lib3mf.get_wrapper()
    model = wrapper.CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    reader.ReadFromFile(str(path))
    warnings = [reader.GetWarning(i) for i in range(reader.GetWarningCount())]
    assert warnings == []
    return model


def _mesh_objects(model):
    it = model.GetMeshObjects()
    out = []
    while it.MoveNext():
        out.append(it.GetCurrentMeshObject())
    return out


def test_lib3mf_reads_our_mesh_3mf_strictly(tmp_path):
    mesh = tessellate(load_lattice("octet").with_counts(2, 2, 1), None, "cnt")
    path = tmp_path / "m.3mf"
    export_mesh(mesh, path)
    model = _lib3mf_read(path)
    assert model.GetUnit() == lib3mf.ModelUnit.MilliMeter
    (obj,) = _mesh_objects(model)
    assert obj.IsManifoldAndOriented()
    assert obj.GetTriangleCount() == len(mesh.faces)
    tri = np.array([list(t.Indices) for t in obj.GetTriangleIndices()])
    pos = np.array([list(p.Coordinates) for p in obj.GetVertices()])
    assert trimesh.Trimesh(pos, tri).volume == pytest.approx(mesh.volume, rel=1e-5)


def test_lib3mf_beam_lattice_with_triangles(tmp_path):
    lat = load_lattice("bcc").with_counts(2, 3, 2)
    ev = lat.evaluate()
    mesh = tessellate(lat, None, "cnt")
    path = tmp_path / "b.3mf"
    write_beam_lattice_3mf(path, ev.center, ev.radius, ev.beam_nodes, mesh=mesh)
    model = _lib3mf_read(path)
    (obj,) = _mesh_objects(model)
    assert obj.IsManifoldAndOriented() and obj.GetTriangleCount() == len(mesh.faces)
    nv = obj.GetVertexCount() - len(ev.center)
    bl = obj.BeamLattice()
    beams, balls = bl.GetBeams(), bl.GetBalls()
    assert len(beams) == len(ev.beam_nodes) and len(balls) == len(ev.center)
    r32 = ev.radius.astype(np.float32)
    idx = np.array([list(b.Indices) for b in beams]) - nv
    assert np.array_equal(idx, ev.beam_nodes)
    assert np.array_equal(np.array([list(b.Radii) for b in beams]), r32[ev.beam_nodes].astype(float))
    assert np.array_equal(np.array([b.Index for b in balls]) - nv, np.arange(len(ev.center)))
    assert np.array_equal(np.array([b.Radius for b in balls]), r32.astype(float))
    pos = np.array([list(p.Coordinates) for p in obj.GetVertices()])[nv:]
    assert np.array_equal(pos, ev.center.astype(np.float32).astype(float))
    assert bl.GetBallOptions()[0] == lib3mf.BeamLatticeBallMode.Mixed
    # the beam extensions are optional: a consumer without them reads a watertight mesh
    with zipfile.ZipFile(path) as z:
        assert b"requiredextensions" not in z.read("3D/3dmodel.model")
    back = read_back(path)
    assert_consumer_clean(back, mesh.volume, rel=1e-5)


# ----- Blender's own importers (headless bpy, in a subprocess: bpy state is global) ----------

BLENDER_SCRIPT = r'''
import json, sys
import bpy  # noqa: I001 - bpy first: it makes bmesh importable
import bmesh
out = {}
for path in sys.argv[1:]:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    ext = path.rsplit(".", 1)[1]
    {"stl": bpy.ops.wm.stl_import, "ply": bpy.ops.wm.ply_import, "obj": bpy.ops.wm.obj_import,
     "glb": bpy.ops.import_scene.gltf}[ext](filepath=path)
    bm = bmesh.new()
    for o in [o for o in bpy.context.scene.objects if o.type == "MESH"]:
        part = bmesh.new()
        part.from_mesh(o.data)
        part.transform(o.matrix_world)
        me = bpy.data.meshes.new("part")
        part.to_mesh(me)
        bm.from_mesh(me)
    co = [v.co[:] for v in bm.verts]
    out[path] = {"faces": len(bm.faces), "bad_edges": sum(len(e.link_faces) != 2 for e in bm.edges),
                 "lo": [min(c[i] for c in co) for i in range(3)], "hi": [max(c[i] for c in co) for i in range(3)]}
print("RESULT" + json.dumps(out))
'''


def test_blender_importers_read_manifold_meshes(tmp_path):
    import subprocess
    import sys

    try:
        import importlib.util

        if importlib.util.find_spec("bpy") is None:
            pytest.skip("bpy is not installed")
    except ValueError:
        pytest.skip("bpy is not installed")
    mesh = tessellate(load_lattice("becots_kagome"), None, "refined", 1)
    paths = []
    for fmt in ("stl", "ply", "obj", "glb"):
        paths.append(str(tmp_path / f"m.{fmt}"))
        export_mesh(mesh, paths[-1])
    script = tmp_path / "import.py"
    script.write_text(BLENDER_SCRIPT)
    out = subprocess.run([sys.executable, str(script), *paths], capture_output=True, text=True, timeout=600)
    line = [x for x in out.stdout.splitlines() if x.startswith("RESULT")]
    assert line, out.stderr[-2000:]
    import json

    res = json.loads(line[0][len("RESULT"):])
    lo, hi = mesh.bounds
    for p in paths:
        r = res[p]
        assert r["bad_edges"] == 0 and r["faces"] == len(mesh.faces)  # every edge has two faces
        scale = 1e-3 if p.endswith(".glb") else 1.0  # Blender shows glTF in metres, Z up like ours
        assert np.allclose(r["lo"], lo * scale, atol=1e-5 * scale)
        assert np.allclose(r["hi"], hi * scale, atol=1e-5 * scale)


# ----- huge coordinates (issue 20: a similarity scaled by 1e10) --------------------------

def _scaled_cubic(cell: float, factor: float = 1.0, n: int = 3):
    from ple import Lattice, Pt, Scaling, Translation, Vec

    lat = Lattice()
    a = lat.add_node(Pt(0.3 * cell, 0.1 * cell, 0), 0.1 * cell)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Scaling(factor, Pt(-cell, 0, 0)) if factor != 1.0 else Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(2, Translation(Vec(0, 0, cell)))
    return lat


def test_keys_of_huge_coordinates_stay_distinct():
    from ple.meshing.tessellate import quantized

    k = quantized(np.array([1e19, 2e19, 1e19 * (1 + 1e-14), np.nan, 0.5e-9, 1.0]), 1e-9)
    assert len({row.tobytes() for row in k}) == 5  # 1e19 and 1e19·(1 + 1e-14) share a key
    assert k[0].tobytes() == k[2].tobytes() and np.all(np.abs(k) < 2**51)


@pytest.mark.parametrize("style", ["cnt", "refined"])
def test_a_lattice_scaled_by_1e10_is_written_closed(tmp_path, style):
    small = tessellate(_scaled_cubic(1.0), None, style, 1)
    for fmt in ("stl", "3mf", "glb"):
        path = tmp_path / f"big.{fmt}"
        n = write_mesh(MeshRequest(_scaled_cubic(1e10), style=style, levels=1), path)
        back = read_back(path)
        assert n == len(back.faces) == len(small.faces)
        scale = 1e-3 if fmt == "glb" else 1.0  # glTF in metres
        assert_consumer_clean(back, small.volume * (1e10 * scale) ** 3, rel=1e-4)


def test_sizes_float32_cannot_hold_are_refused(tmp_path):
    from ple.errors import PleError

    lat = _scaled_cubic(1.0, factor=1e5)  # groups of size 1 beside groups of size 1e10
    for fmt in ("stl", "3mf"):
        with pytest.raises(PleError, match="float32"):
            write_mesh(MeshRequest(lat, style="cnt"), tmp_path / f"x.{fmt}")
        assert not (tmp_path / f"x.{fmt}").exists()
    ok = _scaled_cubic(1.0, factor=10.0)  # within float32's reach: written closed
    write_mesh(MeshRequest(ok, style="cnt"), tmp_path / "ok.stl")
    assert_consumer_clean(read_back(tmp_path / "ok.stl"))
