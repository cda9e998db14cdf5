"""Draws docs/img/body_modes.png: the demo bracket's section at mid-depth with the balls of a
BCC lattice kept by each fill mode (and what the cleanup removes). Run ``python -m tools.body_picture``."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from matplotlib.patches import Circle  # noqa: E402
from ple.bench.body import bcc  # noqa: E402
from ple.filters.body import BodyFilter  # noqa: E402
from ple.filters.cleanup import cleanup_evaluation  # noqa: E402
from ple.io.bodyfile import load_body  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    path = ROOT / "presets" / "bracket.stl"
    body = load_body(path)
    mesh = trimesh.load(path, force="mesh")
    lat = bcc(body.lo, body.hi, 12000)
    ev0 = lat.evaluate()
    ys = np.unique(np.round(ev0.center[:, 1], 9))
    y0 = float(ys[len(ys) // 2])
    section = mesh.section(plane_origin=(0, y0, 0), plane_normal=(0, 1, 0))
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.6))
    panels = [(m, lat.with_filter(BodyFilter(body, m)).evaluate()) for m in ("inside", "centroid", "any")]
    cleaned, report = cleanup_evaluation(panels[2][1])
    panels.append(("any + cleanup", cleaned))
    for ax, (title, ev) in zip(axes, panels):
        for ent in section.entities:
            pts = section.vertices[ent.points]
            ax.plot(pts[:, 0], pts[:, 2], color="0.2", lw=1.2)
        sel = np.abs(ev.center[:, 1] - y0) < 1e-6
        rows = np.flatnonzero(sel)
        for a, b in ev.beam_nodes[sel[ev.beam_nodes[:, 0]] & sel[ev.beam_nodes[:, 1]]]:
            ax.plot(*ev.center[[a, b]][:, [0, 2]].T, color="tab:blue", lw=0.6)
        for n in rows:
            ax.add_patch(Circle(ev.center[n, [0, 2]], ev.radius[n], color="tab:orange", zorder=3))
        ax.set_title(f"{title}: {len(ev.center):,} balls")
        ax.set_aspect("equal")
        ax.set_xlim(body.lo[0] - 0.3, body.hi[0] + 0.3)
        ax.set_ylim(body.lo[2] - 0.3, body.hi[2] + 0.3)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"The demo bracket's section at y = {y0:.2f} and the balls of a BCC lattice kept by each fill mode "
                 f"(cleanup: {report.dangling_nodes} dangling balls, {report.components - 1} loose pieces)")
    fig.tight_layout()
    out = ROOT / "docs" / "img" / "body_modes.png"
    fig.savefig(out, dpi=90)
    print("wrote", out)


if __name__ == "__main__":
    main()
