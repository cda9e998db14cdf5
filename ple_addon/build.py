"""Build the Blender extension: ``python -m ple_addon.build`` (``make extension``).

Stages the add-on (``ple_addon/``), a vendored copy of the core package ``ple`` as the
relative sub-package ``vendor.ple`` (no global ``sys.path`` changes inside Blender), the
presets and the trimesh wheel (for tessellation and export), with the repository's
``blender_manifest.toml`` (plus its ``wheels`` list); then builds and validates
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
NOT_SHIPPED = {"build.py", "batch.py"}  # repository tools, not part of the add-on
IGNORE_NAMES = ("__pycache__", "*.pyc", "*.so", "*.c")  # pure Python: numpy encodes STL, assembles boxes
IGNORE = shutil.ignore_patterns(*IGNORE_NAMES)
NOT_VENDORED = ("cli", "bench")  # the core's doors for the command line: the extension needs only the library layers
WHEELS = ["trimesh>=4.0"]  # pure-Python packages the core needs beyond Blender's own numpy


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


def fetch_wheels(dest: Path) -> list[str]:
    """Download the wheels of ``WHEELS`` (no dependencies: numpy ships with Blender) with pip;
    returns their manifest paths, or [] with a warning when pip cannot get them (offline)."""
    dest.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--python-version", "3.11",
           "--retries", "0", "--timeout", "15", "-d", str(dest), *WHEELS]  # fail fast when offline
    res = subprocess.run(cmd, capture_output=True, text=True)
    found = sorted(dest.glob("*.whl"))
    if res.returncode != 0 or not found:
        print(f"warning: no wheels bundled ({res.stderr.strip()[-300:]}); tessellate/export then need trimesh "
              "installed in Blender's Python", file=sys.stderr)
        return []
    return [f"./wheels/{w.name}" for w in found]


def stage(dest: Path, wheels: bool = True) -> dict:
    """Copy manifest, add-on, vendored core and presets into ``dest`` (and the wheels of
    ``WHEELS``, listed in the staged manifest); returns the manifest."""
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    dest.mkdir(parents=True, exist_ok=True)
    text = (ROOT / "blender_manifest.toml").read_text()
    paths = fetch_wheels(dest / "wheels") if wheels else []
    if paths:  # a top-level key: it goes before the first [table]
        head, sep, tail = text.partition("\n[")
        text = head + "\nwheels = [" + ", ".join(f'"{p}"' for p in paths) + "]\n" + sep + tail
    (dest / "blender_manifest.toml").write_text(text)
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
    shutil.copytree(ROOT / "core" / "ple", vendor / "ple", ignore=shutil.ignore_patterns(*NOT_VENDORED, *IGNORE_NAMES))
    shutil.copytree(ROOT / "presets", vendor / "ple" / "presets", ignore=IGNORE)
    return manifest


def build(out_dir: Path, wheels: bool = True) -> Path:
    tool = blender_ext_tool()
    with tempfile.TemporaryDirectory(prefix="ple-ext-") as tmp:
        src = Path(tmp) / "ple"
        manifest = stage(src, wheels)
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
    parser.add_argument("--no-wheels", action="store_true", help=f"do not bundle {', '.join(WHEELS)}")
    args = parser.parse_args(argv)
    print(build(Path(args.out), wheels=not args.no_wheels))
    return 0


if __name__ == "__main__":
    sys.exit(main())
