"""The hostile user of issue 20 on the doors added after it: ``ple clg …`` and its ``ple-clg/1``
loader, ``slice``, ``skin``, ``fit``, ``check``, ``assemble``, ``--parts``, ``--count``, body
filters (``--body``, ``--grade``), ``--fillet``, the Möbius and warp presets and ``bench``.

Every case must end with exit 0 or 2 (2 where the input is wrong or too big): one line on error,
never a traceback, never the generic out-of-memory line (the budget refuses first), no temporary
left, and nothing the user had changed. Cases run in-process (a fork per program keeps them
contained) under an address-space watchdog of 3 GiB beyond what the test process maps."""

from __future__ import annotations

import json
import os
import resource
from pathlib import Path

import numpy as np
import pytest
from ple.cli.main import main
from ple.io.files import TMP_TAG

PRESETS = Path(__file__).resolve().parents[2] / "presets"
WATCHDOG = 3 << 30


def _vm() -> int:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")


def _write_inputs(d: Path) -> None:
    import trimesh

    plate = json.loads((PRESETS / "clg" / "plate.json").read_text())
    text = json.dumps(plate)

    def put(name: str, data=None, raw: bytes | None = None) -> None:
        (d / name).write_bytes(raw if raw is not None else json.dumps(data, allow_nan=True).encode())

    def edited(key: str, value) -> dict:
        out = json.loads(text)
        out[key] = value
        return out

    def each(d0: dict, keys: tuple, value) -> dict:  # set every `keys` field inside the chunks
        out = json.loads(json.dumps(d0))

        def walk(x):
            if isinstance(x, dict):
                for k in list(x):
                    if k in keys and not isinstance(x[k], dict):
                        x[k] = value
                    else:
                        walk(x[k])
            elif isinstance(x, list):
                for y in x:
                    walk(y)
        walk(out["chunks"])
        return out

    put("plate.json", plate)
    put("deep.json", raw=b'{"format":"ple-clg/1","pattern":' + b"[" * 100_000 + b"]" * 100_000 + b"}")
    name = next(iter(plate["chunks"]))
    chunk = json.dumps(plate["chunks"][name])
    nested = json.dumps(name) + ": " + '{"union": [' * 3000 + chunk + "]}" * 3000
    put("deepchunk.json", raw=text.replace(json.dumps({name: plate["chunks"][name]})[1:-1], nested).encode())
    digits = '"format": "ple-clg/1", "description": ' + "9" * 5000
    put("bigint.json", raw=text.replace('"format": "ple-clg/1"', digits).encode())
    put("badutf.json", raw=b'{"format": "ple-clg/1", "description": "\xff\xfe"}')
    put("nullpattern.json", edited("pattern", None))
    put("listchunks.json", edited("chunks", [1, 2]))
    put("unknown.json", edited("extra", 1))
    put("solid7.json", edited("solid", 7))
    put("matbad.json", edited("materials", {"m": {"replace": 5}}))
    put("array.json", [1, 2, 3])
    put("empty.json", raw=b"")
    for tag, value in (("1e308", 1e308), ("neg", -1), ("str", "big"), ("nested", [[1]]), ("nan", float("nan"))):
        put(f"scale_{tag}.json", each(plate, ("scale",), value))
    for tag, value in (("big", [10**20, 0, 0, 0]), ("99", [0, 0, 0, 99]), ("float", [0.5, 0, 0, 0]), ("null", None)):
        put(f"node_{tag}.json", each(plate, ("node", "from", "to"), value))
    (d / "big.json").write_bytes(b" " * (65 << 20) + b"{}")
    os.mkfifo(d / "fifo.json")
    (d / "dir.json").mkdir()
    for name, body in (("exit", "import sys\n    sys.exit(0)"), ("osexit", "import os\n    os._exit(3)"),
                       ("base", "raise GeneratorExit"), ("none", "return None"), ("loop", "while True: pass"),
                       ("mem", "x = bytearray(20 << 30)"), ("lattice", "return Lattice()")):
        (d / f"prog_{name}.py").write_text(f"def clg():\n    {body}\n")
    (d / "prog_syntax.py").write_text("def clg(:\n")
    (d / "prog_latin1.py").write_bytes(b"# \xe9\ndef clg():\n    return None\n")

    rng = np.random.default_rng(1)
    np.save(d / "pts.npy", rng.random((10, 3)))
    np.save(d / "pts_nan.npy", np.full((4, 3), np.nan))
    np.save(d / "pts_1d.npy", np.zeros(5))
    np.save(d / "pts_obj.npy", np.array([1, "a"], object), allow_pickle=True)
    np.save(d / "pts_str.npy", np.array([["a", "b", "c"]]))
    np.savez(d / "pts.npz", a=np.zeros((3, 3)))
    (d / "pts_hugehdr.npy").write_bytes(b"\x93NUMPY\x01\x00\xff\xff{'descr': '<f8', 'fortran_order': False, "
                                        b"'shape': (100000000000, 3), }")
    np.save(d / "rays.npy", np.hstack([rng.random((10, 3)) - 5, np.tile([1.0, 0, 0], (10, 1))]))
    np.save(d / "rays_zero.npy", np.zeros((5, 6)))

    box = trimesh.creation.box((4, 4, 4))
    box.apply_translation((2, 2, 2))
    box.export(d / "box.stl")
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.45)
    sphere.export(d / "sphere.stl")
    (d / "empty.stl").write_bytes(b"")
    (d / "garbage.stl").write_bytes(rng.bytes(5000))
    (d / "garbage.obj").write_bytes(rng.bytes(5000))
    (d / "garbage.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\n"
                                    b"property float x\nend_header\n" + rng.bytes(100))
    (d / "garbage.glb").write_bytes(b"glTF" + rng.bytes(200))
    (d / "garbage.3mf").write_bytes(rng.bytes(300))
    (d / "hugecount.stl").write_bytes(b"\0" * 80 + (4_000_000_000).to_bytes(4, "little") + b"\0" * 100)
    (d / "text.stl").write_text("solid x\nendsolid x\n")
    opened = trimesh.creation.box()
    opened.faces = opened.faces[:-2]
    opened.export(d / "open.stl")
    (d / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (d / "escape.gltf").write_text(json.dumps({"asset": {"version": "2.0"},
                                               "buffers": [{"uri": "../../../../etc/shadow", "byteLength": 100}]}))
    os.mkfifo(d / "fifo.stl")
    (d / "dir.stl").mkdir()

    (d / "user.txt").write_text("the user's file")
    (d / "userdir").mkdir()
    (d / "userdir" / "notes.txt").write_text("notes")
    (d / "userdir" / "manifest.json").write_text("{}")
    (d / "outdir.npy").mkdir()
    for job, manifest in (("job_broken", "{"), ("job_list", "[1]"), ("job_deep", "[" * 100_000),
                          ("job_escape", json.dumps({"format": "ple-job/1", "kind": "mesh",
                                                     "parts": {"../../user.txt": {"file": "../../user.txt"}}}))):
        (d / job).mkdir()
        (d / job / "manifest.json").write_text(manifest)
    (d / "job_empty").mkdir()
    (d / "job_absolute").mkdir()
    (d / "job_absolute" / "manifest.json").write_text(json.dumps({
        "format": "ple-job/1", "kind": "mesh", "order": [str(d / "user.txt")],
        "parts": {str(d / "user.txt"): {"bytes": 15, "sha256": "0" * 64, "triangles": 0}}}))
    (d / "batch_escape").mkdir()
    (d / "batch_escape" / "manifest.json").write_text(json.dumps({"format": "ple-batch/1",
                                                                  "outputs": [{"file": "../user.txt"}]}))
    (d / "ud").mkdir()
    (d / "ud" / "part_000000.stl").write_text("the user's part")
    flat = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
                           process=False)
    flat.export(d / "flat.stl")
    point = trimesh.Trimesh(np.zeros((4, 3)), [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]], process=False)
    (d / "point.ply").write_bytes(trimesh.exchange.ply.export_ply(point, encoding="ascii"))
    ico = trimesh.creation.icosphere(subdivisions=1, radius=0.4)
    f = ico.faces.copy()
    f[0, 0] = 99999
    (d / "badidx.ply").write_text(
        f"ply\nformat ascii 1.0\nelement vertex {len(ico.vertices)}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
        + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in ico.vertices.tolist())
        + "".join(f"3 {a} {b} {c}\n" for a, b, c in f.tolist()))
    huge = trimesh.creation.icosphere(subdivisions=2, radius=1e30)  # around everything
    huge.export(d / "huge.stl")
    cross = trimesh.creation.box((4e10,) * 3)  # a face through the lattice's middle, triangles 4e10 long
    cross.apply_translation((1 - 2e10, 0, 0))
    cross.export(d / "cross.stl")
    twice = trimesh.creation.box((2, 2, 2))
    twice.apply_translation((3.5, 3.5, 3.5))
    trimesh.util.concatenate([box, twice]).export(d / "selfx.stl")  # closed, intersecting itself
    for args in (["batch", "cubic", "--param", "n=2,3", "--style", "cnt", "--out", d / "batch_dmg"],
                 ["mesh", "cubic", "--param", "n=2", "--style", "cnt", "--parts", d / "job_dmg"]):
        args += ["--scheduler", "sync"]
        assert main([str(a) for a in args]) == 0
    for damaged in (d / "batch_dmg" / "cubic__n-2.stl", d / "job_dmg" / "part_000000.stl"):
        damaged.write_bytes(damaged.read_bytes()[:100])
    for name, line in (("filter5", "lat.filter = 5"), ("uhello", "lat.u = 'hello'"), ("beam3", "lat.beams.append(3)")):
        (d / f"lat_{name}.py").write_text(
            "def lattice():\n    lat = Lattice()\n    a = lat.add_node(Pt(0, 0, 0), 0.1)\n"
            "    lat.add_beam(a, a, 1, 0, 0)\n    lat.set_u(3, Translation(Vec(1, 0, 0)))\n"
            f"    {line}\n    return lat\n")
    _write_round4(d)


def _write_round4(d: Path) -> None:
    """The fourth round's inputs: numbers beyond float64, a repeated beam-pattern, a key of a
    million characters, bodies of side 1e±30 and inside out, a query ball of radius 1e300."""
    import trimesh

    def lattice(radius=0.1, beams=None, **directions) -> dict:
        out = {"format": "ple-lattice/1",
               "nodes": [{"id": "a", "center": [0, 0, 0], "radius": radius},
                         {"id": "b", "center": [0.5, 0, 0], "radius": radius}],
               "beams": beams or [{"from": "a", "to": "b", "offset": [0, 0, 0]},
                                  {"from": "a", "to": "a", "offset": [1, 0, 0]}]}
        out.update(directions)
        return out

    step = {"count": 3, "similarity": {"kind": "translation", "vector": [1, 0, 0]}}
    for name, data in (
            ("r4_scale2.json", lattice(U={"count": 100, "similarity": {"kind": "scaling", "factor": 2,
                                                                        "point": [0, 0, 0]}})),
            ("r4_far.json", lattice(U={"count": 3, "similarity": {"kind": "translation", "vector": [1e99, 0, 0]}})),
            ("r4_tiny.json", lattice(radius=5e-324, U=step)),
            ("r4_twice.json", lattice(beams=[{"from": "a", "to": "b", "offset": [0, 0, 0]}] * 50, U=step)),
            ("r4_key.json", {**lattice(U=step), "k" * 1_000_000: 1})):
        (d / name).write_text(json.dumps(data))
    for side in (1e30, 1e-30):
        trimesh.creation.box((side,) * 3).export(d / f"r4_box_{side:g}.stl")
    inverted = trimesh.creation.box((0.8,) * 3)
    inverted.invert()
    inverted.export(d / "r4_inverted.stl")
    np.save(d / "r4_q.npy", np.array([[0, 0, 0, 1e300]]))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("doors")
    _write_inputs(d)
    return d


def _snapshot(d: Path) -> dict:
    out = {}
    for root, dirs, files in os.walk(d):
        for n in files + dirs:
            p = Path(root) / n
            st = os.lstat(p)
            out[str(p.relative_to(d))] = (st.st_mode, st.st_size if not p.is_dir() else 0, st.st_mtime_ns)
    return out


REFUSE, ANY = "refuse", "any"  # exit 2 (with a needle, when given), or exit 0 or 2
C: list = []


def case(expect, *args, needle: str | None = None, outs=()):
    C.append(pytest.param(expect, [str(a) for a in args], needle, outs, id=" ".join(map(str, args))[:90]))


# ----- ple clg: the ple-clg/1 loader, contained programs, sources --------------------------------------
for src, needle in (("deep.json", "nested deeper"), ("deepchunk.json", "nested deeper"), ("bigint.json", "4300"),
                    ("badutf.json", "UTF-8"), ("nullpattern.json", "pattern"), ("listchunks.json", "chunks"),
                    ("unknown.json", "extra: unknown field"), ("solid7.json", "solid"), ("matbad.json", "materials.m"),
                    ("array.json", "JSON object"), ("empty.json", "malformed JSON"), ("scale_1e308.json", "scale"),
                    ("scale_neg.json", "must be > 0"), ("scale_str.json", "scale"), ("scale_nested.json", "scale"),
                    ("scale_nan.json", "scale"), ("node_big.json", "outside"), ("node_99.json", "unknown node 99"),
                    ("node_float.json", "integer"), ("node_null.json", "node"), ("big.json", "larger than the limit"),
                    ("fifo.json", "not a regular file"), ("dir.json", "is a folder"), ("missing.json", "no such file"),
                    ("../x/plate", "neither"), ("/etc/passwd", "neither"),
                    ("prog_exit.py", "sys.exit(0)"), ("prog_osexit.py", "os._exit(3)"),
                    ("prog_base.py", "GeneratorExit"),
                    ("prog_none.py", "must return a CLG"), ("prog_lattice.py", "must return a CLG"),
                    ("prog_syntax.py", "syntax"), ("prog_latin1.py", "UTF-8")):
    case(REFUSE, "clg", "info", src, needle=needle)
case(REFUSE, "clg", "info", "prog_loop.py", "--timeout", "1", needle="longer than 1 s")
case(REFUSE, "clg", "info", "prog_mem.py", "--max-memory", "512M", needle="out of memory (limit 512 MiB)")
case(REFUSE, "clg", "info", "plate.json", "--param", "x=1", needle="no parameters")
case(REFUSE, "clg", "info", "plate", "--timeout", "nan", needle="timeout")
for p in ("nu=1e9", "nu=-3", "nu=nan", "reach=inf", "x=1", "nu"):
    case(REFUSE, "clg", "info", "connectors", "--param", p)
case(REFUSE, "clg", "mesh", "connectors", "--param", "nu=100", "--param", "nv=100", "--max-memory", "64M",
     "--out", "m.stl")
case(ANY, "clg", "info", "plate")

# --points / --rays arrays
for pts, needle in (("pts_nan.npy", "NaN"), ("pts_1d.npy", "shape"), ("pts_obj.npy", "pts_obj"),
                    ("pts.npz", "pts.npz"), ("pts_str.npy", "numeric"), ("pts_hugehdr.npy", "pts_hugehdr"),
                    ("missing.npy", "no such file"), ("fifo.json", "not a regular file"), ("dir.json", "folder"),
                    ("rays.npy", "shape")):
    case(REFUSE, "clg", "pmc", "plate", "--points", pts, "--out", "o.npy", needle=needle)
for rays, needle in (("pts.npy", "shape"), ("pts_nan.npy", "shape"), ("pts.npz", "pts.npz")):
    case(REFUSE, "clg", "ray", "plate", "--rays", rays, "--out", "r.npy", needle=needle)
case(ANY, "clg", "ray", "plate", "--rays", "rays_zero.npy", "--out", "r0.npy", outs=("r0.npy",))
# outputs that are not files the command may replace
for out, needle in (("userdir", ".npy"), ("outdir.npy", "folder"), ("o.txt", ".npy"),
                    ("missing/o.npy", "does not exist")):
    case(REFUSE, "clg", "pmc", "plate", "--points", "pts.npy", "--out", out, needle=needle)
case(ANY, "clg", "pmc", "plate", "--points", "pts.npy", "--out", "/dev/null")
# voxels, slices, renders, meshes: sizes refused before allocating
for grid, needle in (("0,0,0", "at least 1"), ("2000,2000,2000", "voxels"),
                     ("1200,1200,1200", "voxels"), ("1000,1000,1000", "--max-memory"),
                     ("a,b,c", "integers"), ("10,10", "NX,NY,NZ"),
                     ("99999999999999999999,1,1", "voxels")):
    case(REFUSE, "clg", "voxelize", "plate", "--grid", grid, "--max-memory", "1G", "--out", "v.npy", needle=needle)
for bounds in ("nan,0,0,1,1,1", "0,0,0,1,1", "1,1,1,0,0,0", "0,0,0,inf,1,1", "x"):
    case(REFUSE, "clg", "voxelize", "plate", "--grid", "4,4,4", "--bounds", bounds, "--out", "v.npy", needle="--bounds")
case(REFUSE, "clg", "voxelize", "plate", "--grid", "100,100,100", "--bounds=-1e308,-1e308,-1e308,1e308,1e308,1e308",
     "--out", "v.npy", needle="--bounds")
for layer, pixel, needle in (("0", "0.1", "--layer"), ("-1", "0.1", "--layer"), ("nan", "0.1", "--layer"),
                             ("inf", "0.1", "--layer"), ("1e-9", "0.1", "layers exceed"),
                             ("0.1", "1e-9", "pixels per layer"), ("1e-7", "0.5", "layers exceed")):
    case(REFUSE, "clg", "slice", "plate", "--layer", layer, "--pixel", pixel, "--out", "sl", needle=needle)
for out, needle in (("userdir", "not touching it"), ("user.txt", "not a folder"), ("missing/sl", "does not exist")):
    case(REFUSE, "clg", "slice", "plate", "--layer", "0.5", "--pixel", "0.5", "--out", out, needle=needle)
for size, needle in (("0,0", "size"), ("-5,5", "size"), ("100000,100000", "size"), ("a,b", "size"),
                     ("10", "size"), ("4000,4000", "--max-memory")):
    case(REFUSE, "clg", "render", "plate", "--size", size, "--out", "r.png", needle=needle)
for view in ("nan,0", "inf,inf", "x"):
    case(REFUSE, "clg", "render", "plate", "--size", "8,8", "--passes", "1", "--view", view, "--out", "r.png",
         needle="--view")
for passes in ("0", "-1", "100"):
    case(REFUSE, "clg", "render", "plate", "--size", "8,8", "--passes", passes, "--out", "r.png", needle="--passes")
case(REFUSE, "clg", "render", "plate", "--size", "8,8", "--passes", "1", "--out", "userdir", needle="folder")
for seg in ("0", "-1", "3", "100000"):
    case(REFUSE, "clg", "mesh", "plate", "--segments", seg, "--out", "m.stl", needle="--segments")
for out, needle in (("userdir", "format"), ("m.xyz", "xyz")):
    case(REFUSE, "clg", "mesh", "plate", "--out", out, needle=needle)

# ----- ple slice (a lattice) ------------------------------------------------------------------------------
for layer, pixel, needle in (("0", "0.1", "--layer"), ("nan", "0.1", "--layer"), ("1e-9", "0.1", "layers"),
                             ("0.1", "1e-9", "pixels"), ("1e-7", "0.5", "layers")):
    case(REFUSE, "slice", "cubic", "--param", "n=2", "--layer", layer, "--pixel", pixel, "--out", "sl2", needle=needle)
case(REFUSE, "slice", "cubic", "--param", "n=10000", "--layer", "0.5", "--pixel", "0.5", "--out", "sl2",
     needle="pixels")
case(REFUSE, "slice", "cubic", "--param", "n=2", "--layer", "0.5", "--pixel", "0.5", "--out", "userdir",
     needle="not touching it")
case(REFUSE, "slice", "cubic", "--param", "n=2", "--layer", "0.5", "--pixel", "0.5", "--out", "user.txt",
     needle="not a folder")
case(REFUSE, "slice", "cubic", "--param", "n=2", "--layer", "0.1", "--pixel", "0.1", "--bounds", "0,0,0,1e9,1e9,1e9",
     "--out", "sl3", needle="layers")

# ----- body filters: bad meshes and gradings ---------------------------------------------------------------
for mesh, needle in (("empty.stl", "empty"), ("garbage.stl", "garbage.stl"), ("garbage.obj", "garbage.obj"),
                     ("garbage.ply", "garbage.ply"), ("garbage.glb", "garbage.glb"), ("garbage.3mf", "garbage.3mf"),
                     ("hugecount.stl", "hugecount.stl"), ("text.stl", "empty"), ("open.stl", "not closed"),
                     ("nan.obj", "NaN"), ("escape.gltf", "escape.gltf"), ("fifo.stl", "not a regular file"),
                     ("dir.stl", "folder"), ("missing.stl", "no such file"), ("user.txt", "format")):
    case(REFUSE, "eval", "cubic", "--param", "n=3", "--body", mesh, "--out", "e.npz", needle=needle)
for grade in ("surface:nan:1:1", "0,0,0:0,0,0:1:1", "0,0,0:1,1,1:nan:1", "0,0,0:1,1,1:-1:1", "0,0,0:1,1,1:0:0", "a",
              "1e308,0,0:-1e308,0,0:1:2", "surface:0:1:1", "surface:-1:1:1", "0,0,0:1,1,1:1e308:1"):
    case(REFUSE, "eval", "cubic", "--param", "n=3", "--grade", grade, "--body", "box.stl", "--out", "e.npz",
         needle="--grade")
case(REFUSE, "eval", "cubic", "--param", "n=10000", "--body", "box.stl", "--out", "e.npz", needle="nodes")
case(ANY, "info", "cubic", "--param", "n=10000", "--body", "box.stl")
case(REFUSE, "mesh", "cubic", "--param", "n=10000", "--body", "box.stl", "--out", "m.stl", needle="node-groups")

# ----- check --------------------------------------------------------------------------------------------
for extra, needle in ((("--min-feature", "nan"), "--min-feature"), (("--min-feature", "-1"), "--min-feature"),
                      (("--min-feature", "inf"), "--min-feature"), (("--max-slenderness", "nan"), "--max-slenderness"),
                      (("--max-slenderness", "0"), "--max-slenderness"), (("--region", "0:1e9,0:1,0:1"), "region"),
                      (("--region", "x"), "region")):
    case(REFUSE, "check", "cubic", "--param", "n=3", *extra, needle=needle)
case(REFUSE, "check", "cubic", "--param", "n=10000", needle="limit")
case(REFUSE, "check", "cubic", "--param", "n=10000", "--cleanup", needle="limit")
case(REFUSE, "check", "cubic", "--param", "n=10000", "--body", "box.stl", needle="limit")

# ----- skin ---------------------------------------------------------------------------------------------
for extra in (("--thickness", "0"), ("--thickness", "-1"), ("--thickness", "nan"), ("--thickness", "inf"),
              ("--thickness", "0.5", "--edge", "0"), ("--thickness", "0.5", "--edge", "nan"),
              ("--thickness", "0.5", "--edge", "-2")):
    case(REFUSE, "skin", "cubic", "--param", "n=4", "--body", "box.stl", *extra, "--out", "s.stl",
         needle=extra[-2])
case(REFUSE, "skin", "cubic", "--param", "n=4", "--body", "box.stl", "--thickness", "0.5", "--edge", "1e-6",
     "--out", "s.stl", needle="distance samples")
case(REFUSE, "skin", "cubic", "--param", "n=4", "--thickness", "0.5", "--out", "s.stl", needle="--body")
case(REFUSE, "skin", "cubic", "--param", "n=100", "--body", "box.stl", "--thickness", "0.5", "--max-memory", "64M",
     "--out", "s.stl", needle="--max-memory")
case(REFUSE, "skin", "cubic", "--param", "n=10000", "--body", "box.stl", "--thickness", "0.5", "--out", "s.stl",
     needle="nodes")

# ----- fit ----------------------------------------------------------------------------------------------
for mesh in ("empty.stl", "garbage.stl", "fifo.stl", "dir.stl", "missing.stl", "nan.obj", "hugecount.stl"):
    case(REFUSE, "fit", mesh, "--out", "f.npz", needle=mesh)
for extra, needle in ((("--bound", "0"), "--bound"), (("--bound", "-1"), "--bound"), (("--bound", "nan"), "--bound"),
                      (("--orders", "0"), "--orders"), (("--orders", "256"), "--max-memory"),
                      (("--orders", "-8"), "--orders"),
                      (("--orders", "100000"), "--orders"), (("--orders", "a"), "--orders"),
                      (("--orders", ""), "--orders"),
                      (("--max-terms", "-1"), "--max-terms"), (("--max-terms", "0"), "--max-terms")):
    case(REFUSE, "fit", "sphere.stl", "--normalize", *extra, "--out", "f.npz", needle=needle)
case(REFUSE, "fit", "sphere.stl", "--out", "userdir", needle=".npz")
case(REFUSE, "fit", "open.stl", "--orders", "8", "--out", "f_open.npz", needle="not closed")
case(REFUSE, "fit", "sphere.stl", "--out", "f.txt", needle=".npz")

# ----- assemble and partitioned jobs ----------------------------------------------------------------------
for url in ("job_empty", "job_broken", "job_list", "job_deep", "job_escape", "missing", "user.txt", "userdir",
            "nosuch://x"):
    case(REFUSE, "assemble", url, "--out", "a.stl")
for extra, needle in ((("--parts", "userdir"), "userdir"), (("--parts", "user.txt"), "user.txt"),
                      (("--parts", "p1", "--box-groups", "0"), "--box-groups"),
                      (("--parts", "p1", "--box-groups", "-1"), "--box-groups"),
                      (("--parts", "p1", "--scheduler", "bogus"), "scheduler"),
                      (("--parts", "p1", "--scheduler", "sync", "--workers", "-1"), "--workers"),
                      (("--parts", "nosuch://x", "--scheduler", "sync"), "nosuch")):
    case(REFUSE, "mesh", "cubic", "--param", "n=3", "--out", "pm.stl", *extra, needle=needle)
case(REFUSE, "mesh", "cubic", "--param", "n=10000", "--out", "pm.stl", "--parts", "p3", "--scheduler", "sync",
     needle="parts")
case(REFUSE, "filter", "cubic", "--param", "n=3", "--stencil", "edges:2", "--out", "f.npz", "--parts", "userdir",
     "--scheduler", "sync", needle="userdir")

# ----- outputs that are inputs, damaged meshes, malformed programs -------------------------------------------
case(REFUSE, "mesh", "cubic", "--param", "n=3", "--body", "box.stl", "--out", "box.stl", needle="same file")
case(REFUSE, "skin", "cubic", "--param", "n=3", "--body", "box.stl", "--thickness", "0.5", "--out", "box.stl",
     needle="same file")
case(REFUSE, "clg", "pmc", "plate", "--points", "pts.npy", "--out", "pts.npy", needle="same file")
case(REFUSE, "clg", "voxelize", "plate", "--grid", "4,4,4", "--out", "userdir", needle="userdir")
case(REFUSE, "mesh", "cubic", "--param", "n=3", "--parts", "ud", "--scheduler", "sync", needle="no job manifest")
case(REFUSE, "slice", "cubic", "--param", "n=2", "--layer", "0.5", "--pixel", "0.5", "--parts", "ud", "--scheduler",
     "sync", needle="no job manifest")
case(REFUSE, "assemble", "job_absolute", "--out", "a.stl", needle="plain file name")
case(REFUSE, "batch", "cubic", "--param", "n=2", "--scheduler", "sync", "--out", "batch_escape",
     needle="plain file name")
case(REFUSE, "batch", "cubic", "--param", "n=2", "--scheduler", "bogus", "--out", "b_new", needle="--scheduler")
for extra in (("eval", "cubic", "--param", "n=3", "--body", "badidx.ply", "--out", "e.npz"),
              ("skin", "cubic", "--param", "n=3", "--body", "badidx.ply", "--thickness", "0.1", "--out", "s.stl"),
              ("fit", "badidx.ply", "--normalize", "--out", "f.npz")):
    case(REFUSE, *extra, needle="99999")
for mesh, needle in (("flat.stl", "no volume"), ("point.ply", "one point")):
    case(REFUSE, "fit", mesh, "--normalize", "--orders", "8", "--out", "f.npz", needle=needle)
for name, needle in (("filter5", "filter is int"), ("uhello", "u is str"), ("beam3", "beams[1]")):
    for cmd in (("info",), ("eval", "--out", "e.npz"), ("mesh", "--out", "m.stl")):
        case(REFUSE, cmd[0], f"lat_{name}.py", *cmd[1:], needle=needle)
case(REFUSE, "becots", "connectors", "becots_annulus", "--radius", "1e50", "--out", "cn", needle="non-finite")

# ----- bodies cut by --fill any, damaged outputs that a re-run or assemble must not trust -------------------
case(ANY, "mesh", "cubic", "--param", "n=3", "--body", "huge.stl", "--fill", "any", "--out", "hm.stl",
     outs=("hm.stl",))
case(REFUSE, "mesh", "cubic", "--param", "n=3", "--body", "cross.stl", "--fill", "any", "--out", "hm.stl",
     needle="coarser")
for cmd in (("mesh", "--fill", "any"), ("skin", "--thickness", "0.2")):
    case(REFUSE, cmd[0], "cubic", "--param", "n=3", "--body", "selfx.stl", *cmd[1:], "--out", "hm.stl",
         needle="intersects itself")
case(ANY, "batch", "cubic", "--param", "n=2,3", "--style", "cnt", "--scheduler", "sync", "--out", "batch_dmg",
     outs=("batch_dmg",))
case(REFUSE, "assemble", "job_dmg", "--out", "a.stl", needle="damaged")

# ----- --fillet, Möbius and warp presets -----------------------------------------------------------------
for fillet in ("nan", "-1", "inf", "1e308", "100"):
    case(REFUSE, "mesh", "cubic", "--param", "n=2", "--fillet", fillet, "--out", "fm.stl", needle="--fillet")
case(REFUSE, "mesh", "cubic", "--param", "n=2", "--fillet", "0.5", "--style", "cnt", "--out", "fm.stl",
     needle="--fillet")
for preset, params in (("mobius_slab", ("nu=1e9", "nu=0", "nv=-1", "radius=1e308", "radius=nan", "nu=2.5")),
                       ("rectified_warp", ("nu=1e7", "radius=inf")),
                       ("warped", ("n=1e6", "bend=nan"))):
    for p in params:
        case(REFUSE, "info", preset, "--param", p)

# ----- the fourth round: numbers beyond float64, bounded messages, extreme and inside-out bodies ----------
for lattice_file, needle in (("r4_scale2.json", "loses all precision: the powers of U"),
                             ("r4_far.json", "loses all precision: the powers of U"),
                             ("r4_tiny.json", "underflows to zero scale"), ("r4_twice.json", "repeats beams[0]"),
                             ("r4_key.json", "k" * 79 + "…: unknown field")):
    for cmd in ("info", "check"):
        case(REFUSE, cmd, lattice_file, needle=needle)
case(REFUSE, "biq", "cubic", "--queries", "r4_q.npy", "--out", "h.json", needle="beyond 1e+100")
for side in ("1e+30", "1e-30"):
    case(ANY, "fit", f"r4_box_{side}.stl", "--normalize", "--orders", "8", "--out", "f.npz", outs=("f.npz",))
for extra in ((), ("--normalize",), ("--distance",)):
    case(REFUSE, "fit", "r4_inverted.stl", *extra, "--orders", "8", "--out", "f.npz", needle="--flip")

# ----- bench --------------------------------------------------------------------------------------------
for extra, needle in ((("body", "--sample", "-1"), "--sample"), (("body", "--repeat", "0"), "--repeat"),
                      (("body", "--body", "garbage.stl"), "garbage.stl"),
                      (("body", "--body", "missing.stl"), "missing"),
                      (("mesh", "--lattice", "nope"), "nope"), (("mesh", "--big", "100000"), "--big"),
                      (("mesh", "--region", "-1"), "--region"), (("mesh", "--out", "userdir"), "folder"),
                      (("mesh", "--warped", "-3"), "--warped"), (("mesh", "--levels", "9"), "--levels"),
                      (("curved", "--n", "1"), "--n 1"), (("curved", "--styles", "cnt,zigzag"), "zigzag"),
                      (("curved", "--warped-n", "500"), "--warped-n"), (("startup", "--runs", "0"), "--runs")):
    case(REFUSE, "bench", *extra, needle=needle)


@pytest.mark.parametrize("expect, args, needle, outs", C)
def test_new_doors_refuse_cleanly(folder, expect, args, needle, outs, capsys, monkeypatch):
    monkeypatch.chdir(folder)
    monkeypatch.setenv("PLE_MAX_MEMORY", "1G")
    before = _snapshot(folder)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    resource.setrlimit(resource.RLIMIT_AS, (_vm() + WATCHDOG, hard))  # the watchdog: a runaway fails here
    try:
        try:
            code = main(args)
        except SystemExit as exc:  # argparse: a usage error (exit 2)
            code = exc.code
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
    err = capsys.readouterr().err
    lines = [x for x in err.strip().splitlines() if x]
    if "usage:" in err:  # argparse: its usage, then one error line
        lines = lines[-1:]
    assert "Traceback" not in err, err
    assert code in ((2,) if expect == REFUSE else (0, 2)), (code, err)
    if code == 2:
        assert len(lines) == 1 and lines[0].startswith("ple "), err  # one line (argparse: after its usage)
        assert "out of memory;" not in err, err  # the budget refused it before allocating, not the watchdog
        if needle:
            assert needle in err, (needle, err)
    after = _snapshot(folder)
    assert not [n for n in after if TMP_TAG in n], [n for n in after if TMP_TAG in n]
    for name, state in before.items():
        if not any(name == o or name.startswith(o + "/") for o in outs):
            assert after.get(name) == state, name  # nothing the user had changed
    if code == 2:
        assert set(after) == set(before), set(after) ^ set(before)  # a refusal writes nothing
