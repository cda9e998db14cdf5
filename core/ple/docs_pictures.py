"""Concept pictures for docs/concepts.md, rendered from core results (see ple.docs_build)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .docs_build import DOCS, render
from .preview import balls_beams_mesh
from .program import load_lattice

IMG = DOCS / "img"


def _lattice_mesh(lat, region=None, beam_scale=0.6):
    ev = lat.evaluate(region)
    return balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes, beam_scale=beam_scale)


def steady_rows():
    """Steady rows: one template ball repeated by a translation, a rotation, a scaling and a swirl."""
    from .lattice import Lattice
    from .similarity import Rotation, Scaling, Swirl, Translation
    meshes = []
    rows = [Translation([1.0, 0, 0]), Rotation(0.35, [0, 0, 1], [0, 4, 0]), Scaling(1.12, [-4, -3, 0]),
            Swirl(0.45, [0, 0, 1], [4, -13, 0], 0.93)]
    for n, s in enumerate(rows):
        lat = Lattice()
        a = lat.add_node([0, -3.0 * n, 0], 0.25)
        lat.add_beam(a, a, 1, 0, 0)
        lat.set_u(10, s)
        meshes.append(_lattice_mesh(lat))
    return meshes, None


def cage():
    from .cage import cage_curves
    lat = load_lattice("fig6_3")
    curves = cage_curves(lat, interior=2)
    width = max(len(c) for c in curves)
    padded = np.stack([np.vstack([c, np.repeat(c[-1:], width - len(c), 0)]) for c in curves])
    return [_lattice_mesh(lat, "0:3,0:4,0:5")], padded


PICTURES = {"steady_rows": steady_rows, "cage": cage}


def build_pictures(force: bool = False) -> list[str]:
    done = []
    for name, make in PICTURES.items():
        png = IMG / f"{name}.png"
        if png.is_file() and not force:
            continue
        meshes, curves = make()
        render(Path(png), meshes, curves=curves, view="top" if name == "steady_rows" else "iso")
        done.append(name)
        print(f"  picture {png}", flush=True)
    return done
