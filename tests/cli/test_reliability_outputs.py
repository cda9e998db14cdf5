"""Outputs checked against inputs, finite results, OS errors as user errors, resume that verifies,
signals of the console script only, and the hostile inputs that ended in tracebacks
(docs/reliability.md). Every case runs ``ple`` in-process (``main``) and asserts exit 0 or 2 with
one line, no traceback, nothing of the user's changed and no partial file."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest
import trimesh
from ple.cli.main import main
from ple.errors import PleError
from ple.io.files import TMP_TAG, check_apart, plain_name, strict_json
from reliability_helpers import assert_clean_failure, ple

CLG_PRESETS = Path(__file__).resolve().parents[2] / "presets" / "clg"
BIG = """def lattice(n=6, cell=1.0, radius=0.2):
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), radius * cell)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(n, Translation(Vec(cell, 0, 0)))
    lat.set_v(n, Translation(Vec(0, cell, 0)))
    lat.set_w(n, Translation(Vec(0, 0, cell)))
    return lat
"""


def run(args, capsys) -> tuple[int, str]:
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, err


def refused(args, capsys, *needles) -> str:
    code, err = run(args, capsys)
    lines = [x for x in err.strip().splitlines() if x]
    assert code == 2, (code, err)
    assert len(lines) == 1 and lines[0].startswith("ple "), err
    for n in needles:
        assert n in err, (n, err)
    return err


def digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def no_temporaries(d: Path) -> None:
    left = [p for p in d.rglob("*") if TMP_TAG in p.name]
    assert not left, left


@pytest.fixture
def mesh_file(tmp_path):
    s = trimesh.creation.icosphere(subdivisions=2, radius=1.5)
    s.apply_translation((1.5, 1.5, 1.5))
    s.export(tmp_path / "part.stl")
    return tmp_path / "part.stl"


# ----- 1. inputs are sacred ------------------------------------------------------------------------------
def test_parts_never_go_into_a_users_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ud").mkdir()
    (tmp_path / "ud" / "part_000000.stl").write_text("MINE")
    refused(["mesh", "cubic", "--param", "n=3", "--parts", "ud", "--scheduler", "sync", "--out", "ud.stl"], capsys,
            "--parts ud", "no job manifest")
    assert (tmp_path / "ud" / "part_000000.stl").read_text() == "MINE"
    assert sorted(os.listdir(tmp_path / "ud")) == ["part_000000.stl"]
    assert not (tmp_path / "ud.stl").exists()


@pytest.mark.parametrize("link", ["same", "symlink", "hardlink"])
def test_an_output_that_is_an_input_is_refused(tmp_path, capsys, mesh_file, link):
    out = mesh_file
    if link == "symlink":
        out = tmp_path / "link.stl"
        out.symlink_to(mesh_file)
    elif link == "hardlink":
        out = tmp_path / "hard.stl"
        os.link(mesh_file, out)
    before = digest(mesh_file)
    refused(["mesh", "cubic", "--param", "n=4", "--body", mesh_file, "--out", out], capsys,
            "same file as the input --body")
    refused(["skin", "cubic", "--param", "n=4", "--body", mesh_file, "--thickness", "0.2", "--out", out], capsys,
            "same file as the input --body")
    assert digest(mesh_file) == before
    no_temporaries(tmp_path)


def test_clg_points_are_not_replaced_by_their_answer(tmp_path, capsys):
    pts = tmp_path / "P.npy"
    np.save(pts, np.random.default_rng(0).random((5, 3)))
    before = digest(pts)
    refused(["clg", "pmc", CLG_PRESETS / "shelled.json", "--points", pts, "--out", pts], capsys,
            "same file as the input --points")
    assert digest(pts) == before


def test_an_output_folder_holding_an_input_is_refused(tmp_path, capsys):
    d = tmp_path / "sl"
    d.mkdir()
    (d / ".ple-output.json").write_text(json.dumps({"kind": "ple-slices", "version": 1, "command": "ple slice"}))
    prog = d / "big.py"
    prog.write_text(BIG)
    refused(["slice", prog, "--param", "n=2", "--layer", "0.5", "--pixel", "0.5", "--out", d], capsys,
            "holds the input")
    assert prog.read_text() == BIG


def test_check_apart_compares_files_folders_and_links(tmp_path):
    a = tmp_path / "a.txt"
    a.write_text("x")
    (tmp_path / "l.txt").symlink_to(a)
    with pytest.raises(PleError, match="same file"):
        check_apart({"--out": str(tmp_path / "l.txt")}, {"--in": str(a)})
    with pytest.raises(PleError, match="holds the input"):
        check_apart({"--out": str(tmp_path)}, {"--in": str(a)})
    check_apart({"--out": str(tmp_path / "new.txt")}, {"--in": str(a)})  # a new file: nothing to compare
    check_apart({"--out": "/dev/null"}, {"--in": "/dev/null"})  # written in place, never replaced


@pytest.mark.parametrize("name", ["../victim.stl", "/etc/passwd", "..", "a/b.stl", ""])
def test_manifest_names_are_plain_names(name):
    with pytest.raises(PleError, match="not a plain file name"):
        plain_name(name, "manifest")


def test_assemble_never_follows_a_name_out_of_its_folder(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    victim = tmp_path / "victim.stl"
    victim.write_bytes(b"\0" * 84)
    for n, name in enumerate(["../victim.stl", str(victim)]):
        job = tmp_path / f"job{n}"
        job.mkdir()
        entry = {"bytes": 84, "sha256": digest(victim), "triangles": 0}
        (job / "manifest.json").write_text(json.dumps({"format": "ple-job/1", "kind": "mesh", "settings": {},
                                                       "order": [name], "parts": {name: entry}}))
        refused(["assemble", job, "--out", tmp_path / f"a{n}.stl"], capsys, "not a plain file name")
        assert not (tmp_path / f"a{n}.stl").exists()
    assert victim.read_bytes() == b"\0" * 84


def test_batch_resume_refuses_names_out_of_its_folder(tmp_path, capsys):
    out = tmp_path / "b"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({"format": "ple-batch/1", "outputs": [{"file": "../x.stl"}]}))
    refused(["batch", "cubic", "--param", "n=2", "--scheduler", "sync", "--out", out], capsys, "not a plain file name")


# ----- 2. finite or refused -------------------------------------------------------------------------------
def test_connectors_of_a_huge_radius_are_refused_not_written(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    refused(["becots", "connectors", "becots_annulus", "--radius", "1e50", "--out", "cn"], capsys,
            "radius 1e+50", "non-finite")
    assert not (tmp_path / "cn").exists()


def _flat_tetra(path: Path) -> None:  # closed (every edge shared by two faces), zero volume
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    trimesh.Trimesh(v, f, process=False).export(path)


def test_fit_refuses_flat_open_and_one_point_meshes(tmp_path, capsys):
    _flat_tetra(tmp_path / "flat.stl")
    opened = trimesh.creation.box()
    opened.faces = opened.faces[:-2]
    opened.export(tmp_path / "open.stl")
    point = trimesh.Trimesh(np.zeros((4, 3)), [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]], process=False)
    (tmp_path / "point.ply").write_bytes(trimesh.exchange.ply.export_ply(point, encoding="ascii"))
    for mesh, needle in (("flat.stl", "no volume"), ("open.stl", "not closed"), ("point.ply", "one point")):
        for extra in ([], ["--normalize"]):
            refused(["fit", tmp_path / mesh, "--orders", "8", *extra, "--out", tmp_path / "f.npz"], capsys,
                    mesh, needle)
    assert not (tmp_path / "f.npz").exists()


def test_json_outputs_are_strict():
    assert strict_json({"a": 1.5}) == '{"a": 1.5}'
    with pytest.raises(PleError, match="the fit report holds a non-finite number"):
        strict_json({"hausdorff": float("inf")}, "the fit report")


def test_an_npz_writer_refuses_non_finite_arrays(tmp_path):
    from ple.io.files import save_npz

    with pytest.raises(PleError, match="'center'.*non-finite"):
        save_npz(tmp_path / "x.npz", {"center": np.array([1.0, np.inf])})
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.parametrize("size", [4e10, 1e30])
def test_extreme_bodies_keep_the_right_cells_in_every_mode(tmp_path, size):
    from ple.filters.body import BodyFilter
    from ple.io.bodyfile import load_body
    from ple.program.sources import load_lattice

    (tmp_path / "big.py").write_text(BIG)
    kept = {}
    for s in (1.0, size):
        sph = trimesh.creation.icosphere(subdivisions=3, radius=2.6 * s)
        sph.apply_translation((2.5 * s,) * 3)
        sph.export(tmp_path / "b.stl")
        lat, body = load_lattice(str(tmp_path / "big.py"), {"cell": s}), load_body(tmp_path / "b.stl")
        ev = lat.evaluate()
        kept[s] = [BodyFilter(body, m).node_mask(lat, ev.node_index, ev.center, ev.radius).tolist()
                   for m in ("inside", "any")]
    assert kept[size] == kept[1.0]


@pytest.mark.parametrize("size", ["4e10", "1e30"])
def test_fill_any_meshes_extreme_bodies_as_small_ones(tmp_path, capsys, size):
    (tmp_path / "big.py").write_text(BIG)
    tris = {}
    for s in ("1", size):
        sph = trimesh.creation.icosphere(subdivisions=3, radius=2.6 * float(s))
        sph.apply_translation((2.5 * float(s),) * 3)
        sph.export(tmp_path / f"b{s}.stl")
        code, _ = run(["mesh", tmp_path / "big.py", "--param", f"cell={s}", "--body", tmp_path / f"b{s}.stl",
                       "--fill", "any", "--style", "cnt", "--out", tmp_path / f"m{s}.stl"], capsys)
        assert code == 0
        tris[s] = len(trimesh.load(tmp_path / f"m{s}.stl").faces)
    assert abs(tris[size] - tris["1"]) <= 0.02 * tris["1"], tris  # float32 welds differ at 1e30, not the cells


@pytest.mark.parametrize("size", [1e6, 4e10, 1e30])
def test_fill_any_in_a_huge_body_keeps_the_whole_lattice(tmp_path, capsys, size):
    """A lattice of size 4 inside a sphere of radius ``size`` (all of it inside): every fill mode
    keeps every cell, uncut (the cut's Booleans, at manifold3d's tolerance of 1e-12 of the largest
    coordinate, used to lose the lattice: 0 triangles at 4e10 and 1e30)."""
    (tmp_path / "big.py").write_text(BIG)
    sph = trimesh.creation.icosphere(subdivisions=3, radius=size)
    sph.apply_translation((0.3 * size,) * 3)
    sph.export(tmp_path / "b.stl")
    base = ["mesh", tmp_path / "big.py", "--param", "n=4", "--style", "cnt"]
    assert run([*base, "--out", tmp_path / "all.stl"], capsys)[0] == 0
    whole = trimesh.load(tmp_path / "all.stl")
    for fill in ("any", "inside"):
        assert run([*base, "--body", tmp_path / "b.stl", "--fill", fill, "--out", tmp_path / "m.stl"], capsys)[0] == 0
        m = trimesh.load(tmp_path / "m.stl")
        assert len(m.faces) == len(whole.faces) and m.volume == pytest.approx(whole.volume, rel=1e-9)


def test_a_body_cut_coarser_than_the_lattice_is_refused(tmp_path, capsys):
    """A box 4e10 wide whose face crosses a lattice 1.4 wide: manifold3d would cut within 0.04."""
    (tmp_path / "big.py").write_text(BIG)
    box = trimesh.creation.box(extents=(4e10,) * 3)
    box.apply_translation((1.1 - 2e10, 0, 0))  # through the balls at x = 1
    box.export(tmp_path / "x.stl")
    refused(["mesh", tmp_path / "big.py", "--param", "n=4", "--body", tmp_path / "x.stl", "--fill", "any", "--out",
             tmp_path / "m.stl"], capsys, "x.stl", "4e+10 across", "coarser")
    assert not (tmp_path / "m.stl").exists()


def test_a_self_intersecting_body_is_refused_by_cuts_and_skins(tmp_path, capsys):
    a, b = trimesh.creation.box(extents=(2, 2, 2)), trimesh.creation.box(extents=(2, 2, 2))
    b.apply_translation((1, 1, 1))
    trimesh.util.concatenate([a, b]).export(tmp_path / "sx.stl")  # closed, the boxes overlapping
    for args in (["mesh", "cubic", "--param", "n=3", "--body", tmp_path / "sx.stl", "--fill", "any"],
                 ["skin", "cubic", "--param", "n=3", "--body", tmp_path / "sx.stl", "--thickness", "0.1"]):
        refused([*args, "--out", tmp_path / "m.stl"], capsys, "sx.stl", "intersects itself")
    assert not (tmp_path / "m.stl").exists()


# ----- 3. OS errors are user errors -------------------------------------------------------------------
@contextlib.contextmanager
def small_disk(base: Path, size: str = "20m", readonly: bool = False):
    """A tmpfs of ``size`` (as root), else None (the caller skips)."""
    d = base / "disk"
    d.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)],
                                           capture_output=True).returncode != 0:
        yield None
        return
    try:
        yield d
    finally:
        subprocess.run(["umount", "-l", str(d)], capture_output=True)


def fill(d: Path, leave: int) -> None:
    """Fill the disk ``d`` but ``leave`` bytes."""
    free = os.statvfs(d).f_bavail * os.statvfs(d).f_frsize
    with open(d / "filler", "wb") as fh:
        fh.write(b"\0" * max(0, free - leave))


def test_a_full_disk_is_one_line_and_keeps_the_old_file(tmp_path, capsys, monkeypatch):
    with small_disk(tmp_path) as d:
        if d is None:
            pytest.skip("a tmpfs needs root")
        old = {}
        for name in ("e.npz", "m.ply", "m.glb", "m.obj", "m.3mf", "s.stl"):
            (d / name).write_bytes(b"OLD " + name.encode())
            old[name] = (d / name).read_bytes()
        fill(d, 64 << 10)
        refused(["eval", "cubic", "--param", "n=40", "--out", d / "e.npz"], capsys, "e.npz", "No space left")
        for fmt in ("ply", "glb", "obj", "3mf"):
            refused(["mesh", "cubic", "--param", "n=8", "--style", "cnt", "--out", d / f"m.{fmt}"], capsys,
                    f"m.{fmt}", "No space left")
        # a streamed STL larger than its estimate passes the free-space check, then meets the full disk
        import ple.app.pipeline as pipeline

        monkeypatch.setattr(pipeline, "mesh_triangles", lambda *a, **k: 1.0)  # the one estimate
        refused(["mesh", "cubic", "--param", "n=6", "--out", d / "s.stl"], capsys, "s.stl", "No space left")
        refused(["becots", "connectors", "becots_annulus", "--radius", "0.05", "--out", d / "cn"], capsys,
                "No space left")
        assert not (d / "cn").exists()  # a folder appears complete or not at all
        for name, data in old.items():
            assert (d / name).read_bytes() == data
        no_temporaries(d)


def test_a_read_only_disk_is_one_line(tmp_path, capsys, monkeypatch):
    with small_disk(tmp_path, "4m") as d:
        if d is None:
            pytest.skip("a tmpfs needs root")
        monkeypatch.chdir(tmp_path)
        assert subprocess.run(["mount", "-o", "remount,ro", str(d)]).returncode == 0
        for args in (["slice", "cubic", "--param", "n=2"], ["clg", "slice", CLG_PRESETS / "shelled.json"]):
            err = refused([*args, "--layer", "0.5", "--pixel", "0.5", "--out", d / "sl"], capsys, "Read-only",
                          f"{d / 'sl'}: cannot write")
            assert TMP_TAG not in err, err  # the output is named, not its temporary
        refused(["becots", "connectors", "becots_annulus", "--radius", "0.05", "--out", d / "cn"], capsys, "Read-only")
        refused(["mesh", "cubic", "--param", "n=2", "--style", "cnt", "--out", d / "m.stl"], capsys, "Read-only")
        monkeypatch.setattr("ple.bench.startup.run", lambda args: pytest.fail("the benchmark ran"))
        refused(["bench", "startup", "--out", d / "b.json"], capsys, "Read-only")  # checked before it runs
        assert os.listdir(d) == []


def test_the_streamed_stl_estimate_bounds_the_file(tmp_path):
    from ple.meshing.tessellate import resolve_style, tessellate
    from ple.model.budget import STL_BOUND, mesh_triangles
    from ple.program.sources import load_lattice

    for name in ("cylindrical", "becots_triangle", "fig6_3"):
        lat = load_lattice(name, {})
        r = lat.region("0:3,0:3,0:1")
        for style in ("refined", "chocc", "cnt"):
            lv, seg = resolve_style(style, None, None)
            assert len(tessellate(lat, r, style).faces) <= STL_BOUND * mesh_triangles(lat, r, style, lv, seg)


# ----- 4. resume verifies ---------------------------------------------------------------------------------
def test_batch_resume_redoes_a_damaged_output(tmp_path, capsys):
    out = tmp_path / "b"
    args = ["batch", "cubic", "--param", "n=2", "--style", "cnt", "--scheduler", "sync", "--out", out]
    assert run(args, capsys)[0] == 0
    stl = next(out.glob("*.stl"))
    good = stl.read_bytes()
    stl.write_bytes(good[:100])
    code, _ = run(args, capsys)
    assert code == 0
    assert stl.read_bytes() == good  # made again, not skipped


def test_assemble_refuses_a_damaged_part(tmp_path, capsys):
    parts = tmp_path / "pp"
    assert run(["mesh", "cubic", "--param", "n=2", "--style", "cnt", "--parts", parts, "--scheduler", "sync"],
               capsys)[0] == 0
    part = parts / "part_000000.stl"
    part.write_bytes(part.read_bytes()[:100])
    refused(["assemble", parts, "--out", tmp_path / "a.stl"], capsys, "damaged")
    assert not (tmp_path / "a.stl").exists()


def test_a_bad_scheduler_creates_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("ple.app.cluster.CONNECT_TIMEOUT", 0.5)  # nothing listens on port 1: no need to retry for 5 s
    refused(["batch", "cubic", "--param", "n=2", "--scheduler", "bogus", "--out", "b"], capsys, "--scheduler")
    refused(["mesh", "cubic", "--param", "n=2", "--parts", "pp", "--scheduler", "bogus"], capsys, "--scheduler")
    refused(["batch", "cubic", "--param", "n=2", "--scheduler", "tcp://127.0.0.1:1", "--out", "b"], capsys,
            "cannot reach")
    assert os.listdir(tmp_path) == []


# ----- 5. signals belong to the console script ------------------------------------------------------------
def test_main_leaves_the_signal_handlers_alone(tmp_path, capsys):
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)}
    try:
        for s in (signal.SIGTERM, signal.SIGHUP):
            signal.signal(s, signal.SIG_DFL)
        run(["info", "cubic", "--param", "n=2"], capsys)
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_DFL
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def test_run_restores_the_handlers(monkeypatch):
    import ple.cli.main as cli_main

    seen = {}

    def fake_main():
        seen["term"] = signal.getsignal(signal.SIGTERM)
        return 0

    before = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(cli_main, "main", fake_main)
    with pytest.raises(SystemExit):
        cli_main.run()
    assert seen["term"] is not before  # SIGTERM unwinds while the command runs
    assert signal.getsignal(signal.SIGTERM) is before


# ----- 6. tracebacks become one line ----------------------------------------------------------------------
def _bad_index_ply(path: Path) -> None:
    s = trimesh.creation.icosphere(subdivisions=1, radius=0.4)
    f = s.faces.copy()
    f[0, 0] = 99999
    text = (f"ply\nformat ascii 1.0\nelement vertex {len(s.vertices)}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    text += "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in s.vertices.tolist())
    text += "".join(f"3 {a} {b} {c}\n" for a, b, c in f.tolist())
    path.write_text(text)


def test_a_face_outside_the_vertices_is_named(tmp_path, capsys):
    ply = tmp_path / "bad.ply"
    _bad_index_ply(ply)
    for args in (["eval", "cubic", "--param", "n=3", "--body", ply, "--out", tmp_path / "e.npz"],
                 ["skin", "cubic", "--param", "n=3", "--body", ply, "--thickness", "0.1", "--out", tmp_path / "s.stl"],
                 ["fit", ply, "--normalize", "--orders", "8", "--out", tmp_path / "f.npz"]):
        refused(args, capsys, "bad.ply", "99999")


@pytest.mark.parametrize("line, needle", [("lat.filter = 5", "filter is int 5"),
                                          ("lat.u = 'hello'", "u is str 'hello'"),
                                          ("lat.beams.append(3)", "beams[1] is int 3"),
                                          ("lat.nodes[0].radius = 'x'", "nodes[0].radius")])
def test_a_malformed_returned_lattice_is_named(tmp_path, capsys, line, needle):
    prog = tmp_path / "p.py"
    prog.write_text("def lattice():\n    lat = Lattice()\n    a = lat.add_node(Pt(0, 0, 0), 0.1)\n"
                    f"    lat.add_beam(a, a, 1, 0, 0)\n    lat.set_u(3, Translation(Vec(1, 0, 0)))\n    {line}\n"
                    "    return lat\n")
    for args in (["info", prog], ["eval", prog, "--out", tmp_path / "e.npz"], ["mesh", prog, "--out",
                                                                                 tmp_path / "m.stl"]):
        refused(args, capsys, "p.py", needle)


def test_misleading_messages_say_what_is_wrong(tmp_path, capsys):
    from ple.clg.grid import check_grid
    from ple.io.inputs import load_npy

    with pytest.raises(PleError, match=r"2 grids of .* voxels \(.*\) exceed"):
        check_grid((1600, 1600, 1600), grids=2)
    (tmp_path / "short.stl").write_bytes(b"\0" * 80 + (0).to_bytes(4, "little") + b"\0" * 500)
    refused(["fit", tmp_path / "short.stl", "--out", tmp_path / "f.npz"], capsys, "header counts 0 triangles")
    np.save(tmp_path / "c.npy", np.ones((4, 3), complex))
    with pytest.raises(PleError, match="plain numeric"):
        load_npy(str(tmp_path / "c.npy"), "--points")
    os.umask(0o022)
    assert run(["slice", "cubic", "--param", "n=2", "--layer", "0.5", "--pixel", "0.5", "--out",
                tmp_path / "sl"], capsys)[0] == 0
    assert (tmp_path / "sl").stat().st_mode & 0o777 == 0o755


# ----- 7. budgets before the work -------------------------------------------------------------------------
def _balls_clg(n: int, copies: int = 1) -> dict:
    doc = json.loads((CLG_PRESETS / "shelled.json").read_text())
    doc["pattern"]["nodes"] = [{"id": f"a{i}", "center": [i * 0.05, (i % 7) * 0.1, (i % 5) * 0.1], "radius": 0.06}
                               for i in range(n)]
    doc["pattern"]["beams"] = []
    for k in "UVW":
        doc["pattern"][k]["count"] = copies
    doc["chunks"] = {"X": {"union": [{"ball": {"node": [0, 0, 0, f"a{i}"], "scale": 1}} for i in range(n)]}}
    doc["solid"] = "X"
    return doc


def test_clg_mesh_is_budgeted_before_any_boolean(tmp_path, capsys):
    (tmp_path / "b.json").write_text(json.dumps(_balls_clg(500)))  # 2.56e5 triangles: about 159 MiB
    refused(["clg", "mesh", tmp_path / "b.json", "--max-memory", "100M", "--out", tmp_path / "m.stl"], capsys,
            "--max-memory", "estimated before starting")
    (tmp_path / "c.json").write_text(json.dumps(_balls_clg(300, copies=6)))  # 216 groups: 3.3e7 triangles
    refused(["clg", "mesh", tmp_path / "c.json", "--max-memory", "1G", "--out", tmp_path / "m.stl"], capsys,
            "triangles")


class _Name(str):
    """A node name that counts how often it is compared."""
    compared = 0
    __hash__ = str.__hash__

    def __eq__(self, other):
        _Name.compared += 1
        return str.__eq__(self, other)


def test_many_named_nodes_load_in_linear_work(monkeypatch):
    """A CLG of 20,000 balls × 64 copies took 223 s to load before its budget refused it: each
    named node was compared with every other (added, then resolved), and each leaf's balls
    rebuilt the whole template. Now the names are indexed and the leaves' balls made at once."""
    from ple.clg.ir import clg_from_dict
    from ple.clg.query import compiled
    from ple.model.ir import lattice_from_dict
    from ple.model.lattice import Lattice

    n = 3000
    lat = Lattice()
    names = [_Name(f"a{i}") for i in range(n)]
    for i, name in enumerate(names):
        lat.add_node((i, 0, 0), 0.1, name)
    assert [lat.node_id(x) for x in names] == list(range(n))
    assert _Name.compared < 4 * n  # was about n² (9·10⁶)
    with pytest.raises(PleError, match="used twice"):
        lat.add_node((0, 0, 0), 0.1, "a7")
    _Name.compared = 0
    nodes = [{"id": x, "center": [0, 0, 0], "radius": 0.1} for x in names]
    assert len(lattice_from_dict({"format": "ple-lattice/1", "nodes": nodes}).nodes) == n  # the IR reader too
    assert _Name.compared < 4 * n
    with pytest.raises(PleError, match=r"nodes\[3\].id: 'a0' is used twice"):
        lattice_from_dict({"format": "ple-lattice/1", "nodes": nodes[:3] + nodes[:1]})
    lat.nodes[5].name = "renamed"  # in place: found by the scan the index falls back to
    assert lat.node_id("renamed") == 5
    lat.nodes = lat.nodes[:10]
    with pytest.raises(PleError, match="unknown node id 'a20'"):
        lat.node_id("a20")
    built = {"templates": 0}
    centers = Lattice.template_centers.fget

    def counted(self):
        built["templates"] += 1
        return centers(self)

    monkeypatch.setattr(Lattice, "template_centers", property(counted))
    compiled(clg_from_dict(_balls_clg(n, copies=2)))
    assert built["templates"] < 10  # was one per leaf (3,000)


def test_info_on_balls_overlapping_everything_is_bounded(tmp_path):
    (tmp_path / "big.py").write_text(BIG)
    r = ple("info", tmp_path / "big.py", "--param", "n=10", "--param", "radius=2.5", cwd=tmp_path)
    assert r.returncode in (0, 2), r.stderr
    if r.returncode == 2:
        assert_clean_failure(r)
    assert r.peak_rss < 2 << 30


def test_check_of_balls_overlapping_everything_is_refused_before_testing(tmp_path, capsys):
    (tmp_path / "big.py").write_text(BIG)
    args = ["check", tmp_path / "big.py", "--param", "n=8", "--param", "radius=3"]
    refused(args + ["--region", "0:8,0:8,0:8"], capsys, "candidate pairs", "--max-pairs")  # explicit elements
    refused(args + ["--max-pairs", "1e5"], capsys, "candidate pairs", "--max-pairs")  # anchors of the steady path
    refused(args + ["--max-pairs", "nan"], capsys, "--max-pairs")
    assert run(["check", tmp_path / "big.py", "--param", "n=3", "--param", "radius=3"], capsys)[0] == 1


def test_nested_clg_mesh_is_budgeted_before_any_boolean(tmp_path, capsys):
    """14³ groups of the beam-of-beams are refused at once by their leaves alone (they reached
    2.7 GB under --max-memory 500M); 3³ groups once their nested material is meshed (its bound is
    several times loose); both estimates, bound and as meshed, bound the real mesh of 2³ groups."""
    from ple.clg.ir import clg_from_dict
    from ple.clg.query import compiled
    from ple.meshing.clg import estimated_triangles, mesh_compiled, nested_materials, solid_triangles

    doc = json.loads((CLG_PRESETS / "beam_of_beams.json").read_text())
    doc["pattern"]["W"] = {"count": 14, "similarity": {"kind": "translation", "vector": [0, 0, 2]}}
    for k in "UV":
        doc["pattern"][k]["count"] = 14
    (tmp_path / "n.json").write_text(json.dumps(doc))
    refused(["clg", "mesh", tmp_path / "n.json", "--max-memory", "500M", "--out", tmp_path / "m.stl"], capsys,
            "triangles", "nested materials not counted yet", "use fewer groups")
    for k in "UVW":
        doc["pattern"][k]["count"] = 3
    (tmp_path / "n.json").write_text(json.dumps(doc))
    refused(["clg", "mesh", tmp_path / "n.json", "--max-memory", "500M", "--out", tmp_path / "m.stl"], capsys,
            "nested materials as meshed", "use fewer groups")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["n.json"]
    for k in "UVW":
        doc["pattern"][k]["count"] = 2
    comp = compiled(clg_from_dict(doc))
    real = len(mesh_compiled(comp, 16).faces)
    (sub,) = nested_materials(comp)
    as_meshed = solid_triangles(comp, 16, {id(sub): len(mesh_compiled(sub, 16).faces)})
    assert real <= as_meshed <= solid_triangles(comp, 16)
    assert estimated_triangles(comp, 16) == as_meshed  # what ple bench clg_budget reports
