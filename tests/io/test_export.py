"""Exports: the binary STL writer (parsed back byte by byte), trimesh formats, 3MF with the
Beam Lattice extension (parsed with lxml), atomic writes, and the ``ple mesh`` command."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import trimesh
from lxml import etree
from ple.app.pipeline import write_chunks
from ple.cli.main import main
from ple.errors import PleError
from ple.io.export import NS_BALLS, NS_BEAM, NS_CORE, export_mesh, write_beam_lattice_3mf, write_stl
from ple.meshing.tessellate import iter_triangles, tessellate
from ple.program.sources import load_lattice


def read_stl(path):
    data = path.read_bytes()
    count = int(np.frombuffer(data[80:84], "<u4")[0])
    rec = np.frombuffer(data[84:], np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    assert len(data) == 84 + 50 * count
    return count, rec


def test_binary_stl_streams_chunks(tmp_path):
    rng = np.random.default_rng(0)
    chunks = [rng.normal(size=(k, 3, 3)) for k in (5, 0, 17)]
    path = tmp_path / "t.stl"
    assert write_stl(path, iter(chunks)) == 22
    count, rec = read_stl(path)
    assert count == 22
    allv = np.concatenate(chunks).astype(np.float32)
    assert np.array_equal(rec["v"], allv)
    n = np.cross(allv[:, 1] - allv[:, 0], allv[:, 2] - allv[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.allclose(rec["n"], n, atol=1e-5)


def test_failed_write_leaves_no_file(tmp_path):
    path = tmp_path / "t.stl"
    path.write_bytes(b"old")

    def chunks():
        yield np.zeros((2, 3, 3))
        raise PleError("boom")

    with pytest.raises(PleError):
        write_stl(path, chunks())
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["t.stl"]


def test_snapped_chunks_match_a_per_corner_snap(tmp_path):
    """Indexed chunks are snapped once per vertex (``snap_faces``); the file must equal rounding
    every corner of every triangle to the grid on its own and dropping triangles with two equal
    corners (computed here independently), for 1 and 3 encoding threads."""
    rng = np.random.default_rng(3)
    g = 2.0**-10
    chunks, expect = [], []
    for k in (40, 0, 300):
        v = rng.uniform(-4, 4, size=(k // 2 + 3, 3))
        near = rng.uniform(-g / 4, g / 4, size=(len(v[1::7]), 3))
        v[1::7] = v[::7][: len(v[1::7])] + near  # collapse onto a neighbour
        f = rng.integers(0, len(v), size=(k, 3))
        chunks.append((v, f))
        tri = np.round(v[f] / g) * g
        keep = [len({tuple(c) for c in t}) == 3 for t in tri]
        expect.append(tri[np.array(keep, bool)].astype(np.float32).reshape(-1, 3, 3))
    expect = np.concatenate(expect)
    assert 0 < len(expect) < 340  # some triangles do collapse
    for workers in (1, 3):
        path = tmp_path / f"w{workers}.stl"
        assert write_stl(path, iter(chunks), grid=g, workers=workers) == len(expect)
        count, rec = read_stl(path)
        assert np.array_equal(rec["v"], expect)


def test_threaded_write_failure_leaves_no_file(tmp_path):
    path = tmp_path / "t.stl"
    path.write_bytes(b"old")

    def chunks():
        for _ in range(5):
            yield np.zeros((2, 3, 3))
        raise PleError("boom")

    with pytest.raises(PleError):
        write_stl(path, chunks(), workers=2)
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["t.stl"]


@pytest.mark.parametrize("fmt", ["stl", "ply", "obj", "glb", "3mf"])
def test_mesh_formats_round_trip(tmp_path, fmt):
    mesh = tessellate(load_lattice("cubic").with_counts(2, 2, 1), style="cnt")
    path = tmp_path / f"m.{fmt}"
    export_mesh(mesh, path)
    back = trimesh.load(path, force="mesh")
    assert len(back.faces) == len(mesh.faces)
    scale = 1e-3 if fmt == "glb" else 1.0  # glTF is in metres, our unit is mm
    assert back.volume == pytest.approx(mesh.volume * scale**3, rel=1e-5)


@pytest.mark.parametrize("fmt", ["ply", "3mf", "obj"])
def test_boxes_written_as_one_mesh(tmp_path, fmt):
    lat = load_lattice("cubic")
    want = tessellate(lat, "0:3,0:2,0:2", "cnt")
    count = write_chunks(tmp_path / f"m.{fmt}", iter_triangles(lat, "0:3,0:2,0:2", "cnt", max_groups=2))
    got = trimesh.load(tmp_path / f"m.{fmt}", force="mesh")
    assert count == len(want.faces) == len(got.faces) and got.is_watertight
    assert np.isclose(got.volume, want.volume, rtol=1e-5)  # float32 files, snapped to the region grid


def test_beam_lattice_3mf(tmp_path):
    lat = load_lattice("bcc").with_counts(2, 3, 2)
    ev = lat.evaluate()
    path = tmp_path / "b.3mf"
    write_beam_lattice_3mf(path, ev.center, ev.radius, ev.beam_nodes)
    with zipfile.ZipFile(path) as z:
        assert {"[Content_Types].xml", "_rels/.rels", "3D/3dmodel.model"} <= set(z.namelist())
        root = etree.fromstring(z.read("3D/3dmodel.model"))
    ns = {"c": NS_CORE, "b": NS_BEAM, "b2": NS_BALLS}
    assert root.tag == f"{{{NS_CORE}}}model"
    verts = root.findall(".//c:vertices/c:vertex", ns)
    beams = root.findall(".//b:beamlattice/b:beams/b:beam", ns)
    balls = root.findall(".//b:beamlattice/b2:balls/b2:ball", ns)
    assert root.findall(".//c:triangles/c:triangle", ns) == []
    assert len(verts) == len(ev.center) and len(balls) == len(ev.center) and len(beams) == len(ev.beam_nodes)
    xyz = np.array([[float(v.get(k)) for k in "xyz"] for v in verts])
    assert np.array_equal(xyz, ev.center.astype(np.float32).astype(float))  # float32, written exactly
    v12 = np.array([[int(b.get("v1")), int(b.get("v2"))] for b in beams])
    assert np.array_equal(v12, ev.beam_nodes)
    r1 = np.array([float(b.get("r1")) for b in beams])
    assert np.allclose(r1, ev.radius[ev.beam_nodes[:, 0]], rtol=1e-8)
    lattice = root.find(".//b:beamlattice", ns)
    assert lattice.get(f"{{{NS_BALLS}}}ballmode") == "mixed"
    assert float(lattice.get("minlength")) > 0


def test_ple_mesh_command(tmp_path, capsys):
    out = tmp_path / "m.stl"
    assert main(["mesh", "cubic", "--param", "n=2", "--style", "cnt", "--out", str(out), "--check"]) == 0
    text = capsys.readouterr().out
    report = json.loads(text[text.index("{"):])
    assert report["watertight"] and report["winding_consistent"]
    assert report["euler_characteristic"] == trimesh.load(out).euler_number
    assert abs(report["relative_volume_error"]) < 0.5
    assert main(["mesh", "cubic", "--param", "n=2", "--out", str(tmp_path / "b.3mf"), "--beam-lattice"]) == 0
    assert zipfile.is_zipfile(tmp_path / "b.3mf")


@pytest.mark.parametrize("argv,msg", [
    (["--out", "X.xyz"], "unknown mesh format"),
    (["--out", "X.stl", "--beam-lattice"], "--beam-lattice writes 3MF"),
    (["--out", "X.stl", "--style", "refined", "--levels", "12"], "levels"),
    (["--out", "X.stl", "--region", "0:9,0:1,0:1"], "region"),
])
def test_ple_mesh_bad_input(tmp_path, capsys, argv, msg):
    argv = [a.replace("X", str(tmp_path / "x")) for a in argv]
    assert main(["mesh", "cubic", "--param", "n=2", *argv]) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
