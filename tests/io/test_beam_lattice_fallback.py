"""The beam-lattice 3MF (``ple mesh … --beam-lattice``) and its fallback mesh (``--fallback``), read
back by lib3mf in strict mode, an independent reader: the balls and beams as the lattice evaluates
them, the triangles exactly those of the streamed STL of the same style (boxes welded into one
manifold, oriented mesh), and with ``none`` a valid beams-only package."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest
from ple.app.pipeline import MeshRequest, write_beam_lattice, write_mesh
from ple.cli.main import main
from ple.io import threemf
from ple.io.export import STL_RECORD
from ple.program.sources import load_lattice

from tests.meshing.test_unclean import random_unclean_lattice

lib3mf = pytest.importorskip("lib3mf")


def _read(path):
    """(the one mesh object, vertex positions (V, 3), triangle indices (F, 3)) as lib3mf reads the file
    strictly, without warnings."""
    model = lib3mf.get_wrapper().CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    reader.ReadFromFile(str(path))
    assert [reader.GetWarning(i) for i in range(reader.GetWarningCount())] == []
    it = model.GetMeshObjects()
    objs = []
    while it.MoveNext():
        objs.append(it.GetCurrentMeshObject())
    (obj,) = objs
    pos = np.array([list(p.Coordinates) for p in obj.GetVertices()]).reshape(-1, 3)
    tri = np.array([list(t.Indices) for t in obj.GetTriangleIndices()], np.int64).reshape(-1, 3)
    return obj, pos, tri


def _assert_beams_are_the_lattice(obj, pos, ev):
    """Balls and cone beams: vertex ids after the triangle mesh's, radii and centres in float32."""
    nv = len(pos) - len(ev.center)
    bl = obj.BeamLattice()
    beams, balls = bl.GetBeams(), bl.GetBalls()
    assert len(beams) == len(ev.beam_nodes) and len(balls) == len(ev.center)
    r32 = ev.radius.astype(np.float32).astype(float)
    assert np.array_equal(np.array([list(b.Indices) for b in beams]) - nv, ev.beam_nodes)
    assert np.array_equal(np.array([list(b.Radii) for b in beams]), r32[ev.beam_nodes])
    assert np.array_equal(np.array([b.Index for b in balls]) - nv, np.arange(len(ev.center)))
    assert np.array_equal(np.array([b.Radius for b in balls]), r32)
    assert np.array_equal(pos[nv:], ev.center.astype(np.float32).astype(float))
    assert bl.GetBallOptions()[0] == lib3mf.BeamLatticeBallMode.Mixed
    return nv


def _canonical(tri: np.ndarray) -> np.ndarray:
    """Triangles (F, 3, 3), each turned (orientation kept) to start at its smallest corner, sorted."""
    first = np.lexsort(tri.transpose(2, 0, 1)[::-1], axis=1)[:, 0]
    turned = tri[np.arange(len(tri))[:, None], (first[:, None] + np.arange(3)) % 3]
    flat = turned.reshape(len(tri), 9)
    return flat[np.lexsort(flat.T[::-1])]


@pytest.mark.parametrize("fallback,levels", [("cnt", None), ("chocc", None), ("refined", 1)])
def test_fallback_is_the_streamed_mesh_welded(tmp_path, fallback, levels):
    lat = load_lattice("bcc").with_counts(3, 2, 2)
    path = tmp_path / "b.3mf"
    # boxes of 2 groups: hubs repeated across every box boundary are welded into one vertex each
    got = write_beam_lattice(MeshRequest(lat, style=fallback, levels=levels, max_groups=2, workers=2), path,
                             fallback=fallback)
    stl = tmp_path / "m.stl"
    n = write_mesh(MeshRequest(lat, style=fallback, levels=levels), stl)
    obj, pos, tri = _read(path)
    ev = lat.evaluate()
    nv = _assert_beams_are_the_lattice(obj, pos, ev)
    assert got == {"balls": len(ev.center), "beams": len(ev.beam_nodes), "triangles": n} and len(tri) == n
    assert obj.IsManifoldAndOriented() and tri.max() < nv  # the triangles use the mesh's vertices only
    assert len(np.unique(pos[:nv], axis=0)) == nv  # welded: no vertex twice
    records = np.fromfile(stl, STL_RECORD, offset=84)["vertices"].astype(float)
    assert np.array_equal(_canonical(pos[tri]), _canonical(records))  # the same triangles, oriented alike
    with zipfile.ZipFile(path) as z:
        assert b"requiredextensions" not in z.read("3D/3dmodel.model")  # consumers without beams print it


def test_fallback_none_is_a_valid_beams_only_package(tmp_path):
    lat = load_lattice("octet").with_counts(2, 2, 1)
    path = tmp_path / "b.3mf"
    assert main(["mesh", "octet", "--param", "n=2", "--region", "0:2,0:2,0:1", "--beam-lattice", "--fallback", "none",
                 "--out", str(path)]) == 0
    obj, pos, tri = _read(path)
    assert len(tri) == 0 and obj.GetTriangleCount() == 0
    _assert_beams_are_the_lattice(obj, pos, load_lattice("octet", ["n=2"]).evaluate("0:2,0:2,0:1"))
    assert len(pos) == len(lat.evaluate().center)
    with zipfile.ZipFile(path) as z:
        assert z.testzip() is None
        assert b'requiredextensions="b b2"' in z.read("3D/3dmodel.model")  # beams only: the extensions are needed


def test_default_fallback_is_cnt(tmp_path, capsys):
    path = tmp_path / "b.3mf"
    assert main(["mesh", "bcc", "--param", "n=2", "--beam-lattice", "--out", str(path)]) == 0
    assert "(cnt)" in capsys.readouterr().out
    stl = tmp_path / "m.stl"
    n = write_mesh(MeshRequest(load_lattice("bcc", ["n=2"]), style="cnt"), stl)
    obj, pos, tri = _read(path)
    assert len(tri) == n and obj.IsManifoldAndOriented()
    # an explicit --style still names it (as before --fallback); the two disagreeing are refused
    assert main(["mesh", "bcc", "--param", "n=2", "--beam-lattice", "--style", "chocc", "--out", str(path)]) == 0
    assert "(chocc)" in capsys.readouterr().out
    for argv in (["--beam-lattice", "--style", "chocc", "--fallback", "cnt"], ["--fallback", "cnt"],
                 ["--beam-lattice", "--style", "balls-beams"]):
        assert main(["mesh", "bcc", "--param", "n=2", *argv, "--out", str(tmp_path / "x.3mf")]) == 2
    assert not (tmp_path / "x.3mf").exists()


def test_unclean_fallback_is_the_union_mesh(tmp_path):
    lat = random_unclean_lattice(1)
    info = {}
    path = tmp_path / "u.3mf"
    write_beam_lattice(MeshRequest(lat, style="cnt"), path, fallback="cnt", info=info)
    assert len(info["unclean"].nodes) > 0
    obj, pos, tri = _read(path)
    assert len(tri) and obj.IsManifoldAndOriented()
    _assert_beams_are_the_lattice(obj, pos, lat.evaluate())


def test_model_text_does_not_depend_on_the_slices(monkeypatch):
    """The model is written ROWS rows at a time: the bytes are those of one slice."""
    lat = load_lattice("bcc").with_counts(2, 1, 1)
    ev = lat.evaluate()
    v = np.random.default_rng(0).uniform(-1, 1, (40, 3))
    f = np.random.default_rng(1).integers(0, 40, (70, 3))
    texts = []
    for rows in (1, 7, 1 << 16):
        monkeypatch.setattr(threemf, "ROWS", rows)
        buf = io.StringIO()
        threemf.write_model(buf, v, f, lattice=(ev.center, ev.radius, ev.beam_nodes))
        texts.append(buf.getvalue())
    assert texts[0] == texts[1] == texts[2]
