"""Concept pictures for docs/concepts.md, rendered from core results (see tools.docs_build)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from ple.algebra.similarity import Rotation, Scaling, Swirl, Translation
from ple.meshing.preview import balls_beams_mesh
from ple.meshing.tessellate import tessellate
from ple.model.cage import base_frame, cage_curves, direction_frame
from ple.model.lattice import Lattice
from ple.program.sources import load_lattice

from tools.demo import DEFAULT_PARAMS, DEFAULT_PRESET
from tools.render import DOCS, render

IMG = DOCS / "img"


def _lattice_mesh(lat, region=None, beam_scale=0.6):
    ev = lat.evaluate(region)
    return balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes, beam_scale=beam_scale)


def steady_rows():
    """Steady rows: one template ball repeated by a translation, a rotation, a scaling and a swirl."""
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
    lat = load_lattice("fig6_3")
    return [_lattice_mesh(lat, "0:3,0:4,0:5")], _padded(cage_curves(lat, interior=2))


def _padded(curves: list) -> np.ndarray:
    width = max(len(c) for c in curves)
    return np.stack([np.vstack([c, np.repeat(c[-1:], width - len(c), 0)]) for c in curves])


def _arrows(frames: list[np.ndarray], scale: float):
    """Frames (4x4, columns X, Y, Z, O) drawn as three thin beams each (a ball at the origin)."""
    centers, radii, beams = [], [], []
    for m in frames:
        o = m[:3, 3]
        base = len(centers)
        centers.append(o)
        radii.append(0.08 * scale)
        for axis in range(3):
            centers.append(o + m[:3, axis] / np.linalg.norm(m[:3, axis]) * scale)
            radii.append(0.03 * scale)
            beams.append((base, base + axis + 1))
    return balls_beams_mesh(np.array(centers), np.array(radii), np.array(beams), beam_scale=0.5)


def frames():
    """The handles of the GUI: placement G and the U, V, W frames (cumulative) over the cage."""
    lat = load_lattice("warped")
    g = lat.placement.matrix
    handles = [g @ base_frame(lat)] + [g @ direction_frame(lat, a, cumulative=True) for a in "uvw"]
    return [_lattice_mesh(lat, "0:4,0:4,0:4"), _arrows(handles, 3.0)], _padded(cage_curves(lat, interior=0))


def becots_corners():
    """A BeCOTS slab and its four corners A, B, C, D (thesis §4.2) as large balls."""
    lat = load_lattice("becots_triangle")
    corners = lat.becots.field.corners + lat.template_centers[0]
    return [_lattice_mesh(lat), balls_beams_mesh(corners, np.full(4, 0.3), np.zeros((0, 2), int))], None


def lil():
    """Lattice-in-Lattice: the fine nodes kept (orange) where they meet the coarse lattice (blue)."""
    lat = load_lattice("hier_lil2", {"n": 20, "coarse_cells": 2})
    kept = lat.evaluate()
    coarse = lat.filter.coarse.evaluate()
    return [balls_beams_mesh(kept.center, kept.radius, kept.beam_nodes, beam_scale=0.6),
            balls_beams_mesh(coarse.center, coarse.radius * 0.25, coarse.beam_nodes)], None


def chocc():
    """CNT, CHoCC and refined tessellations of the same octet cell, side by side."""
    lat = load_lattice("octet", {"n": 1, "radius": 0.08})
    meshes = []
    for n, style in enumerate(("cnt", "chocc", "refined")):
        m = tessellate(lat, style=style)
        m.apply_translation([1.6 * n, 0, 0])
        meshes.append(m)
    return meshes, None


def demo():
    """What ``make demo`` makes: the LiL-filtered hierarchical lattice, refined and watertight."""

    return [tessellate(load_lattice(DEFAULT_PRESET, DEFAULT_PARAMS), style="refined", levels=2)], None


def slabs():
    """A thick octet on curved rows (every hub shrunk: one cluster with no free beam) meshed in
    slabs (``ple.meshing.slabs``), each slab its own colour, drawn apart along the cut axis."""
    import trimesh
    from ple.meshing import slabs as slab_mod
    from ple.meshing.tessellate import Tessellator
    from ple.meshing.unions import clusters, piece_estimate

    lat = Lattice()
    a = lat.add_node((0, 0, 0), 0.2)
    for off in [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (-1, 1, 0), (1, 0, 1), (-1, 0, 1), (0, 1, 1),
                (0, -1, 1)]:
        lat.add_beam(a, a, *off)
    lat.set_u(5, Translation((1, 0, 0)))
    lat.set_v(5, Rotation(0.06, (0, 0, 1), (-16, 0, 0)))
    lat.set_w(2, Translation((0, 0, 1)))
    tess = Tessellator(lat, lat.region(), "cnt", 0, 16)
    report, ev = tess.find_unclean()
    c = clusters(report, ev.beam_nodes, ev.center, ev.radius)[0]
    pieces = slab_mod.unite_in_slabs(c, ev.center, ev.radius, ev.beam_nodes, {}, tess.grid,
                                     piece_estimate(c)[0] * 2 // 3)
    axis = int(np.argmax(np.ptp(ev.center, axis=0)))
    out = []
    for n, (v, f) in enumerate(pieces):
        shift = np.zeros(3)
        shift[axis] = 0.6 * n
        out.append(trimesh.Trimesh(v + shift, f, process=False))
    return out, None


PICTURES = {"steady_rows": steady_rows, "cage": cage, "frames": frames, "becots_corners": becots_corners,
            "lil": lil, "chocc": chocc, "demo": demo, "slabs": slabs}


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
