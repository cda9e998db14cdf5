"""Pictures for docs/seeds.md (Möbius and TMI slabs, rectified warp, fitted field, fillets),
rendered from core results: ``python -m tools.seeds_pictures [--force]``."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh
from ple import Lattice, Pt, Translation, Vec
from ple.filters.fit import fit_mesh
from ple.filters.implicit import FourierField, ImplicitFilter
from ple.meshing.tessellate import tessellate
from ple.model.mobius import TMIMap
from ple.program.sources import load_lattice

from tools.render import DOCS, render

IMG = DOCS / "img"
PRESETS = Path(__file__).resolve().parent.parent / "presets"


def _iso_curves(tmi: TMIMap, n: int = 8, samples: int = 80) -> np.ndarray:
    """The TMI map's iso-curves u = i/n and v = j/n (loxodromes), as polylines (L, P, 3)."""
    t = np.linspace(0, 1, samples)
    lines = []
    for k in range(n + 1):
        for z in (tmi(np.full(samples, k / n), t), tmi(t, np.full(samples, k / n))):
            lines.append(np.stack([z.real, z.imag, np.full(samples, 0.2)], axis=1))
    return np.array(lines)


def tmi():
    """A TMI slab of five points with its loxodrome iso-curves (thesis Fig. 11.6)."""
    lat = load_lattice(str(PRESETS / "tmi_slab.py"))
    fig = TMIMap.from_five(0, 4, 0.5 + 4j, 4.5 + 5j, 2 - 0.6j)
    return [tessellate(lat, style="refined", levels=2)], _iso_curves(fig)


def mobius():
    """A Möbius steady slab of three Möbius frames (thesis Fig. 11.5, right)."""
    return [tessellate(load_lattice(str(PRESETS / "mobius_slab.py")), style="refined", levels=2)], None


def warp():
    """A rectified steady warp: a regular slab bent, tapered and twisted (thesis Fig. 3.2)."""
    return [tessellate(load_lattice(str(PRESETS / "rectified_warp.py")), style="refined", levels=2)], None


def fitted():
    """A cubic lattice filtered by a field fitted (ple fit) to an octahedron-shaped cell."""
    octa = trimesh.creation.icosphere(2, 1.0)
    v = octa.vertices / np.abs(octa.vertices).sum(axis=1)[:, None] * 0.42  # onto the octahedron |x|+|y|+|z| = .42
    res = fit_mesh(v, octa.faces, bound=0.03, orders=(8, 16, 32))
    fld = FourierField(res.field.freqs, res.field.coeffs, res.field.n, cell=10.0,
                       placement=Translation(Vec(5, 5, 5)), symmetric=True)
    lat = load_lattice("cubic", {"n": 20})
    lat.set_filter(ImplicitFilter(fld, 0.0))
    return [tessellate(lat, style="refined", levels=1)], None


def fillet():
    """A corner junction, plain (left) and filleted with Eq. 6 (right, size 0.3 ball radii)."""
    lat = Lattice()
    a = lat.add_node(Pt(0, 0, 0), 0.15)
    for off in ((1, 0, 0), (0, 1, 0), (0, 0, 1)):
        lat.add_beam(a, a, *off)
    for setter, vec in ((lat.set_u, Vec(1, 0, 0)), (lat.set_v, Vec(0, 1, 0)), (lat.set_w, Vec(0, 0, 1))):
        setter(2, Translation(vec))
    plain = tessellate(lat, region="0:1,0:2,0:2", style="refined", levels=3)
    fil = tessellate(lat, region="0:1,0:2,0:2", style="refined", levels=3, fillet=0.3)
    fil.apply_translation([2.2, 0, 0])
    return [plain, fil], None


PICTURES = {"seeds_tmi": (tmi, "top"), "seeds_mobius": (mobius, "top"), "seeds_warp": (warp, "iso"),
            "seeds_fitted": (fitted, "iso"), "seeds_fillet": (fillet, "iso")}


def main(force: bool = False) -> None:
    for name, (make, view) in PICTURES.items():
        png = IMG / f"{name}.png"
        if png.is_file() and not force:
            continue
        meshes, curves = make()
        render(png, meshes, curves=curves, view=view)
        print(f"  picture {png}", flush=True)


if __name__ == "__main__":
    main("--force" in sys.argv)
