"""Pictures for the docs and the demo: meshes rendered by Blender (Workbench through EGL) in a
subprocess, then palette-quantized so they stay small in the repository."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
RENDER = Path(__file__).resolve().parent / "render_mesh.py"


def render(out_png: Path, meshes: list, size: str = "640x480", curves: np.ndarray | None = None,
           view: str = "iso") -> None:
    """Render trimesh meshes (and polylines (L, P, 3)) to ``out_png`` in a subprocess."""
    out_png.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="ple-render-") as tmp:
        args = [sys.executable, str(RENDER), str(out_png)]
        for n, m in enumerate(meshes):
            p = Path(tmp) / f"m{n}.ply"
            m.export(p)
            args.append(str(p))
        args += ["--size", size, "--view", view]
        if curves is not None:
            cpath = Path(tmp) / "curves.npz"
            np.savez(cpath, lines=curves)
            args += ["--curves", str(cpath)]
        env = dict(os.environ, BLENDER_USER_RESOURCES=tmp)
        proc = subprocess.run(args, capture_output=True, text=True, env=env)
        if proc.returncode != 0 or not out_png.is_file():
            raise RuntimeError(f"render of {out_png.name} failed: {proc.stderr.strip()[-400:]}")
    _shrink(out_png)


def _shrink(png: Path) -> None:
    """Palette-quantize a rendered PNG (docs pictures stay small in the repository)."""
    from PIL import Image  # optional: only the docs tooling needs pillow

    with Image.open(png) as im:
        small = im.convert("RGB").quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    small.save(png, optimize=True)
