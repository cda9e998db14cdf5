"""Build the Blender extension: ``python -m ple_addon.build`` (``make extension``).

Stages the add-on (``ple_addon/``), a vendored copy of the core package ``ple`` as the
relative sub-package ``vendor.ple`` (no global ``sys.path`` changes inside Blender) and the
presets, with the repository's ``blender_manifest.toml``; then builds and validates
``dist/ple-<version>.zip`` with Blender's ``blender_ext.py``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
NOT_SHIPPED = {"build.py", "render_docs.py", "batch.py"}  # repository tools, not part of the add-on
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc")


def blender_ext_tool() -> Path:
    """Blender's extension command line tool, from the installed bpy module."""
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        sys.exit("error: the bpy module is not installed (pip install bpy==5.0.1)")
    found = sorted(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        sys.exit("error: blender_ext.py not found in the bpy module")
    return found[-1]


def stage(dest: Path) -> dict:
    """Copy manifest, add-on, vendored core and presets into ``dest``; returns the manifest."""
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    dest.mkdir(parents=True, exist_ok=True)
    shutil.copy2(ROOT / "blender_manifest.toml", dest / "blender_manifest.toml")
    for f in sorted((ROOT / "ple_addon").iterdir()):
        if f.name in NOT_SHIPPED or f.name.startswith((".", "__pycache__")):
            continue
        if f.is_dir():
            shutil.copytree(f, dest / f.name, ignore=IGNORE)
        else:
            shutil.copy2(f, dest / f.name)
    vendor = dest / "vendor"
    vendor.mkdir(exist_ok=True)
    (vendor / "__init__.py").write_text('"""Vendored copy of the PLE core package (built by ple_addon/build.py)."""\n')
    shutil.copytree(ROOT / "core" / "ple", vendor / "ple", ignore=IGNORE)
    shutil.copytree(ROOT / "presets", vendor / "ple" / "presets", ignore=IGNORE)
    return manifest


def build(out_dir: Path) -> Path:
    tool = blender_ext_tool()
    with tempfile.TemporaryDirectory(prefix="ple-ext-") as tmp:
        src = Path(tmp) / "ple"
        manifest = stage(src)
        out_dir.mkdir(parents=True, exist_ok=True)
        zip_path = out_dir / f"{manifest['id']}-{manifest['version']}.zip"
        for cmd in (["validate", str(src)],
                    ["build", "--source-dir", str(src), "--output-filepath", str(zip_path)],
                    ["validate", str(zip_path)]):
            res = subprocess.run([sys.executable, str(tool), *cmd], capture_output=True, text=True)
            if res.returncode != 0:
                sys.exit(f"error: blender_ext {cmd[0]} failed:\n{res.stdout}{res.stderr}")
    return zip_path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "dist"), help="output folder (default: dist/)")
    args = parser.parse_args(argv)
    print(build(Path(args.out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
