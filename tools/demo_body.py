"""Writes the demo body shipped with the presets: ``presets/bracket.stl``, an L-bracket with a
bolt hole through its upright (manifold3d Booleans), and ``presets/bracket_fill.json``, an
octahedral (BCC) lattice filling it. Run ``python -m tools.demo_body`` to regenerate both."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from manifold3d import Manifold
from ple import Lattice, Pt, Translation, Vec, save_ir
from ple.filters.body import BodyFilter
from ple.io.bodyfile import load_body

PRESETS = Path(__file__).resolve().parent.parent / "presets"


def bracket() -> trimesh.Trimesh:
    base = Manifold.cube((8.0, 4.0, 1.6))
    upright = Manifold.cube((1.6, 4.0, 6.0))
    rib = Manifold.cube((1.8, 0.8, 1.8), True).rotate((0, 45, 0)).translate((1.6, 2.0, 1.6))  # a gusset
    hole = Manifold.cylinder(3.0, 0.8, 0.8, 40).rotate((0, 90, 0)).translate((-0.5, 2.0, 4.0))
    bolt = Manifold.cylinder(3.0, 0.6, 0.6, 40).translate((5.8, 2.0, -0.5))
    solid = (base + upright + rib) - hole - bolt
    m = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts))


def fill(cell: float = 0.5) -> Lattice:
    """A BCC lattice over the bracket's box, kept where its balls lie inside the bracket."""
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.07)
    b = lat.add_node(Pt(cell / 2, cell / 2, cell / 2), 0.07)
    for off in ((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1), (1, 1, 1)):
        lat.add_beam(a, b, *(-o for o in off))
    lat.set_u(17, Translation(Vec(cell, 0, 0)))
    lat.set_v(9, Translation(Vec(0, cell, 0)))
    lat.set_w(13, Translation(Vec(0, 0, cell)))
    lat.meta["description"] = "BCC lattice filling the demo L-bracket (bracket.stl), balls wholly inside"
    lat.set_filter(BodyFilter(load_body(PRESETS / "bracket.stl"), "inside"))
    return lat


if __name__ == "__main__":
    bracket().export(PRESETS / "bracket.stl")
    save_ir(fill(), PRESETS / "bracket_fill.json", resolved=False)
    print("wrote", PRESETS / "bracket.stl", PRESETS / "bracket_fill.json")
