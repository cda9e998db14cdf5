"""Our files handed to the tools users load them in, outside Python: the Khronos glTF
validator (node), admesh (STL repair statistics) and PrusaSlicer's command line (``--info`` on
STL and 3MF, ``--export-gcode`` of the beam-lattice 3MF). ``make setup`` installs them (the
``consumers`` target); a test skips, naming the tool, only where it could not be installed."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from ple.io.export import export_mesh, write_beam_lattice_3mf
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice

VALIDATE_JS = r"""
const validator = require(process.argv[2]);
const data = require('fs').readFileSync(process.argv[3]);
validator.validateBytes(new Uint8Array(data), {maxIssues: 50}).then(r => {
  console.log(JSON.stringify({errors: r.issues.numErrors, warnings: r.issues.numWarnings,
    infos: r.issues.numInfos, hints: r.issues.numHints, messages: r.issues.messages}));
}, e => { console.error(String(e)); process.exit(3); });
"""

MESHES = {  # a clean preset, the formerly folding kagome, an unclean lattice united with manifold3d
    "cubic_refined2": ("cubic", [], "0:3,0:3,0:3", "refined", 2),
    "kagome_refined2": ("becots_kagome", [], None, "refined", 2),
    "octet_thick_refined2": ("octet", ["n=2", "radius=0.1"], None, "refined", 2),
    "annulus_cnt_unclean": ("becots_annulus", [], None, "cnt", None),
}


@pytest.fixture(scope="module", params=list(MESHES))
def mesh(request):
    name, params, region, style, levels = MESHES[request.param]
    return tessellate(load_lattice(name, params), region, style, levels)


def _gltf_validator() -> Path:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (make setup installs nodejs and gltf-validator)")
    places = [Path(sys.prefix) / "node" / "node_modules"]
    npm = shutil.which("npm")
    if npm:
        root = subprocess.run([npm, "root", "-g"], capture_output=True, text=True).stdout.strip()
        if root:
            places.append(Path(root))
    for p in places:
        if (p / "gltf-validator" / "package.json").is_file():
            return p / "gltf-validator"
    pytest.skip("the npm package gltf-validator is not installed (make setup: npm install --prefix .venv/node)")


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} is not installed (make setup installs it with apt-get)")
    return path


def test_khronos_gltf_validator_accepts_our_glb(tmp_path, mesh):
    module = _gltf_validator()
    export_mesh(mesh, tmp_path / "m.glb")
    script = tmp_path / "validate.js"
    script.write_text(VALIDATE_JS)
    out = subprocess.run(["node", str(script), str(module), str(tmp_path / "m.glb")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]
    assert report["infos"] == 0 and report["hints"] == 0, report["messages"]


def _admesh_stats(text: str) -> dict:
    keys = {"facets": r"Number of facets\s*:\s*(\d+)\s+(\d+)", "parts": r"Number of parts\s*:\s*(\d+)",
            "disconnected": r"Total disconnected facets\s*:\s*(\d+)\s+(\d+)",
            "degenerate": r"Degenerate facets\s*:\s*(\d+)", "edges_fixed": r"Edges fixed\s*:\s*(\d+)",
            "removed": r"Facets removed\s*:\s*(\d+)", "added": r"Facets added\s*:\s*(\d+)",
            "reversed": r"Facets reversed\s*:\s*(\d+)", "backwards": r"Backwards edges\s*:\s*(\d+)",
            "normals_fixed": r"Normals fixed\s*:\s*(\d+)", "volume": r"Volume\s*:\s*([-0-9.eE+]+)"}
    out = {}
    for k, pat in keys.items():
        m = re.search(pat, text)
        assert m, f"admesh printed no {k!r}:\n{text[-2000:]}"
        out[k] = [float(g) for g in m.groups()]
    return out


def test_admesh_finds_nothing_to_repair(tmp_path, mesh):
    admesh = _tool("admesh")
    written = len(mesh.faces) - export_mesh(mesh, tmp_path / "m.stl")["dropped_faces"]  # zero-area ones
    out = subprocess.run([admesh, str(tmp_path / "m.stl")], capture_output=True, text=True, errors="replace",
                         timeout=600)  # admesh may echo bytes of its own buffers that are not UTF-8
    assert out.returncode == 0, out.stderr[-2000:]
    s = _admesh_stats(out.stdout)
    assert s["facets"] == [written, written]
    assert s["disconnected"] == [0, 0]
    for k in ("degenerate", "edges_fixed", "removed", "added", "reversed", "backwards", "normals_fixed"):
        assert s[k] == [0], (k, s)
    assert s["volume"][0] == pytest.approx(mesh.volume, rel=1e-4)


def _prusa_info(path: Path) -> dict:
    exe = _tool("prusa-slicer")
    out = subprocess.run([exe, "--info", str(path)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, (out.stdout + out.stderr)[-2000:]
    info = dict(re.findall(r"^(\w+) = (.*)$", out.stdout, re.M))
    assert info, out.stdout[-2000:]
    return info


@pytest.mark.parametrize("fmt", ["stl", "3mf"])
def test_prusaslicer_reads_a_manifold_mesh(tmp_path, mesh, fmt):
    path = tmp_path / f"m.{fmt}"
    written = len(mesh.faces) - export_mesh(mesh, path)["dropped_faces"]
    info = _prusa_info(path)
    assert info["manifold"] == "yes"
    assert int(info["number_of_facets"]) == written
    assert float(info["volume"]) == pytest.approx(mesh.volume, rel=1e-4)


def test_prusaslicer_slices_the_beam_lattice_3mf(tmp_path):
    exe = _tool("prusa-slicer")
    lat = load_lattice("octet")
    region = lat.region("0:2,0:2,0:2")
    ev = lat.evaluate(region)
    mesh = tessellate(lat, region, "cnt")
    path = tmp_path / "beams.3mf"
    write_beam_lattice_3mf(path, ev.center, ev.radius, ev.beam_nodes, mesh=mesh)
    info = _prusa_info(path)  # a slicer without beam support reads the triangles
    assert info["manifold"] == "yes" and int(info["number_of_facets"]) == len(mesh.faces)
    gcode = tmp_path / "beams.gcode"
    out = subprocess.run([exe, "--export-gcode", "--scale-to-fit", "30,30,30", str(path), "--output", str(gcode)],
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, (out.stdout + out.stderr)[-2000:]
    text = gcode.read_text()
    assert text.count("\nG1 ") > 1000 and ";LAYER_CHANGE" in text
