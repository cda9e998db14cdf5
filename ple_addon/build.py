"""Build the Blender extension: ``python -m ple_addon.build`` (``make extension``).

Stages the add-on (``ple_addon/``), a vendored copy of the core package ``ple`` as the
relative sub-package ``vendor.ple`` (no global ``sys.path`` changes inside Blender), the
presets and the trimesh wheel (for tessellation and export), with the repository's
``blender_manifest.toml`` (plus its ``wheels`` list); then builds and validates
``dist/ple-<version>.zip`` with Blender's ``blender_ext.py``.

The wheels are downloaded once, by ``python -m ple_addon.build --fetch-wheels`` (``make wheels``,
which ``make extension`` and ``make test`` run first), into ``build/wheels/``; a build only copies
what that folder holds, so building (and every test that builds) needs no network.
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
WHEEL_DIR = ROOT / "build" / "wheels"  # filled by --fetch-wheels (make wheels), read by every build


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


def fetch_wheels(dest: Path = WHEEL_DIR) -> bool:
    """Download the wheels of ``WHEELS`` (no dependencies: numpy ships with Blender) with pip into
    ``dest``, replacing what it held (the network, once: ``make wheels``); False with a warning, and
    ``dest`` unchanged, when pip cannot get them."""
    with tempfile.TemporaryDirectory(prefix="ple-wheels-") as tmp:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--python-version",
               "3.11", "--retries", "0", "--timeout", "15", "-d", tmp, *WHEELS]  # fail fast when offline
        res = subprocess.run(cmd, capture_output=True, text=True)
        found = sorted(Path(tmp).glob("*.whl"))
        if res.returncode != 0 or not found:
            print(f"warning: could not download {', '.join(WHEELS)} ({res.stderr.strip()[-300:]}); the extension is "
                  "then built without them and tessellate/export need trimesh installed in Blender's Python",
                  file=sys.stderr)
            return False
        dest.mkdir(parents=True, exist_ok=True)
        for old in dest.glob("*.whl"):
            old.unlink()
        for w in found:
            shutil.copy2(w, dest / w.name)
    return True


def cached_wheels(src: Path, dest: Path) -> list[str]:
    """Copy the wheels found in ``src`` (never downloading) into ``dest``; their manifest paths, or []
    with a warning when ``src`` holds none."""
    found = sorted(src.glob("*.whl")) if src.is_dir() else []
    if not found:
        print(f"warning: no wheels in {src} (make wheels downloads them); tessellate/export then need trimesh "
              "installed in Blender's Python", file=sys.stderr)
        return []
    dest.mkdir(parents=True, exist_ok=True)
    for w in found:
        shutil.copy2(w, dest / w.name)
    return [f"./wheels/{w.name}" for w in found]


def stage(dest: Path, wheels: Path | None = WHEEL_DIR) -> dict:
    """Copy manifest, add-on, vendored core and presets into ``dest`` (and the wheels found in the
    folder ``wheels``, listed in the staged manifest; None: none); returns the manifest."""
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    dest.mkdir(parents=True, exist_ok=True)
    text = (ROOT / "blender_manifest.toml").read_text()
    paths = cached_wheels(wheels, dest / "wheels") if wheels is not None else []
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


def build(out_dir: Path, wheels: Path | None = WHEEL_DIR) -> Path:
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
    parser.add_argument("--wheels", default=str(WHEEL_DIR),
                        help="folder of the wheels to bundle (default: build/wheels/)")
    parser.add_argument("--no-wheels", action="store_true", help=f"do not bundle {', '.join(WHEELS)}")
    parser.add_argument("--fetch-wheels", action="store_true",
                        help=f"only download {', '.join(WHEELS)} into --wheels (the network; exit 1 if it cannot)")
    args = parser.parse_args(argv)
    if args.fetch_wheels:
        return 0 if fetch_wheels(Path(args.wheels)) else 1
    print(build(Path(args.out), wheels=None if args.no_wheels else Path(args.wheels)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
