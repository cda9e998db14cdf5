"""Regenerate docs/tessellation.md's table "Consumers: lattice × format × consumer".

Every lattice of the table is meshed once, written by ``export_mesh`` to each format (default
unit mm), and read back as a consumer reads it (trimesh, equal coordinates merged into one
vertex); then: triangles read back, watertight and every edge on two faces once in each
direction, manifold3d's status, exact self-intersecting face pairs (``ple.meshing.selfcheck``),
and for 3MF lib3mf in strict mode. The rows between the table's header and the first blank line
after it are replaced.

Usage: ``.venv/bin/python tools/consumer_table.py`` (a few minutes: fig6_3's union and the exact
checks).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import lib3mf
import manifold3d
import numpy as np
from ple.io.export import export_mesh, read_back
from ple.io.formats import FORMAT_NAMES
from ple.meshing.selfcheck import count_self_intersections
from ple.meshing.tessellate import tessellate
from ple.meshing.weld import edge_manifold
from ple.program.sources import load_lattice

DOC = Path(__file__).resolve().parents[1] / "docs" / "tessellation.md"
HEADER = ("| lattice, style | format | triangles | watertight & oriented | manifold3d | self-intersecting pairs "
          "| lib3mf (strict) |")
CASES = [("cubic", (3, 3, 3), "refined", 2), ("bcc", (2, 2, 2), "refined", 2), ("octet", (2, 2, 2), "cnt", 0),
         ("becots_kagome", None, "refined", 2), ("fig6_3", None, "refined", 1), ("becots_annulus", None, "cnt", 0)]


def lib3mf_strict(path) -> str:
    model = lib3mf.get_wrapper().CreateModel()
    reader = model.QueryReader("3mf")
    reader.SetStrictModeActive(True)
    reader.ReadFromFile(str(path))
    warnings = reader.GetWarningCount()
    it = model.GetMeshObjects()
    manifold = all(it.GetCurrentMeshObject().IsManifoldAndOriented() for _ in iter(it.MoveNext, False))
    return f"{warnings} warnings, manifold {manifold}"


def rows() -> list[str]:
    out = []
    with tempfile.TemporaryDirectory() as d:
        for name, counts, style, levels in CASES:
            lat = load_lattice(name)
            region = f"0:{counts[0]},0:{counts[1]},0:{counts[2]}" if counts else None
            mesh = tessellate(lat, region, style, levels)
            rep = mesh.metadata.get("ple_unclean")
            label = f"{name} {region or 'all'} {style}{f' {levels}' if style == 'refined' else ''}"
            if rep is not None and len(rep.nodes):
                label += f" (unclean: {len(rep.nodes):,} hubs united)"
            for fmt in FORMAT_NAMES:
                path = Path(d) / f"{name}.{fmt}"
                export_mesh(mesh, path)
                back = read_back(path, as_stored=True)
                f = np.asarray(back.faces)
                topo = edge_manifold(f)
                ok = topo == {"bad_edges": 0, "oriented": True} and back.is_watertight
                m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(back.vertices, np.float32),
                                                        tri_verts=f.astype(np.uint32)))
                pairs = count_self_intersections(back.vertices, f)["self_intersecting_pairs"]
                l3 = lib3mf_strict(path) if fmt == "3mf" else "—"
                out.append(f"| {label} | {fmt} | {len(f):,} | {'yes' if ok else 'NO'} | {m.status().name} | "
                           f"{pairs:,} | {l3} |")
                print(out[-1], flush=True)
    return out


def main() -> int:
    text = DOC.read_text()
    lines = text.splitlines()
    start = lines.index(HEADER) + 2  # after the header and its rule
    end = next(i for i in range(start, len(lines)) if not lines[i].startswith("|"))
    lines[start:end] = rows()
    DOC.write_text("\n".join(lines) + "\n")
    print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
