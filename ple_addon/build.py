"""Build the Blender extension: ``python -m ple_addon.build`` (``make extension``).

Stages the add-on (``ple_addon/``), a vendored copy of the core package ``ple`` as the
relative sub-package ``vendor.ple`` (no global ``sys.path`` changes inside Blender), the
presets and the wheels of every package the core imports beyond Blender's own numpy (``WHEELS``:
trimesh, scipy, manifold3d, rtree), with the repository's ``blender_manifest.toml`` plus its
``platforms`` and ``wheels``; then builds and validates one zip per platform,
``dist/ple-<version>-<platform>.zip``, with Blender's ``blender_ext.py``. ``--platform this`` (the
default) builds this machine's; ``--platform all`` one zip for each of ``PLATFORMS``;
``--no-wheels`` one pure-Python ``ple-<version>.zip`` that needs the packages installed in
Blender's Python.

The wheels are downloaded once, by ``python -m ple_addon.build --fetch-wheels`` (``make wheels``,
which ``make extension`` and ``make test`` run first), into ``build/wheels/``; a build only copies
what that folder holds, so building (and every test that builds) needs no network.
"""

from __future__ import annotations

import argparse
import platform as host
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
NOT_SHIPPED = {"build.py", "batch.py"}  # repository tools, not part of the add-on
IGNORE_NAMES = ("__pycache__", "*.pyc", "*.so", "*.pyd", "*.c")  # compiled modules are added by ``compiled_modules``
IGNORE = shutil.ignore_patterns(*IGNORE_NAMES)
NOT_VENDORED = ("cli", "bench")  # the core's doors for the command line: the extension needs only the library layers
# every package the vendored core imports beyond Blender's own (numpy, requests, zstandard), pinned to
# versions the test suite runs: trimesh (meshes, files), scipy (body fill, pullback queries, checks),
# manifold3d (local unions of unclean hubs, skins, CLG meshes), rtree (trimesh's proximity queries)
WHEELS = ["trimesh==5.2.0", "scipy==1.17.1", "manifold3d==3.5.4", "rtree==1.4.1"]
# Blender's platforms and the pip platform tags their wheels may carry (Blender's Python 3.11)
PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_14_0_arm64", "macosx_12_0_arm64", "macosx_11_0_arm64"),
    "macos-x64": ("macosx_10_15_x86_64", "macosx_10_14_x86_64", "macosx_10_13_x86_64", "macosx_10_9_x86_64"),
}
WHEEL_DIR = ROOT / "build" / "wheels"  # filled by --fetch-wheels (make wheels), read by every build


def this_platform() -> str:
    """This machine's Blender platform name (``linux-x64``, ``macos-arm64``, …)."""
    system = {"Linux": "linux", "Windows": "windows", "Darwin": "macos"}.get(host.system(), host.system().lower())
    machine = {"x86_64": "x64", "AMD64": "x64", "amd64": "x64", "arm64": "arm64", "aarch64": "arm64"}.get(
        host.machine(), host.machine())
    return f"{system}-{machine}"


def wheel_platforms(name: str) -> set[str]:
    """The Blender platforms a wheel file serves, read from its platform tags (PEP 425): ``any``
    serves all of them, ``universal2`` both macOS ones."""
    out = set()
    for tag in name.removesuffix(".whl").split("-")[-1].split("."):
        if tag == "any":
            return set(PLATFORMS)
        if tag.startswith(("manylinux", "musllinux")) and tag.endswith("x86_64"):
            out.add("linux-x64")
        elif tag == "win_amd64":
            out.add("windows-x64")
        elif tag.startswith("macosx"):
            out |= {p for p, arch in (("macos-arm64", "arm64"), ("macos-x64", "x86_64"))
                    if tag.endswith((arch, "universal2"))}
    return out


def _package(spec_or_wheel: str) -> str:
    return spec_or_wheel.split("=")[0].split("-")[0].lower().replace("_", "-")


def wheels_for(plat: str, folder: Path) -> list[Path]:
    """The wheels in ``folder`` that serve ``plat``, one per package of ``WHEELS``; SystemExit
    naming the packages that have none there (``make wheels`` fetches them)."""
    found = {_package(w.name): w for w in sorted(folder.glob("*.whl")) if plat in wheel_platforms(w.name)}
    missing = [_package(spec) for spec in WHEELS if _package(spec) not in found]
    if missing:
        sys.exit(f"error: no {plat} wheel of {', '.join(missing)} in {folder} (make wheels downloads them)")
    return [found[_package(spec)] for spec in WHEELS]


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
    """Download the wheels of ``WHEELS`` for every platform of ``PLATFORMS`` (no dependencies:
    numpy ships with Blender) with pip into ``dest``, replacing what it held (the network, once:
    ``make wheels``); False with a warning, and ``dest`` unchanged, when pip cannot get them all."""
    with tempfile.TemporaryDirectory(prefix="ple-wheels-") as tmp:
        for plat, tags in PLATFORMS.items():
            cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", "--python-version",
                   "3.11", "--implementation", "cp", *(f"--platform={t}" for t in tags), "--retries", "0",
                   "--timeout", "15", "-d", tmp, *WHEELS]  # fail fast when offline
            res = subprocess.run(cmd, capture_output=True, text=True)
            if res.returncode != 0:
                print(f"warning: could not download the {plat} wheels of {', '.join(WHEELS)} "
                      f"({res.stderr.strip()[-300:]})", file=sys.stderr)
                return False
        dest.mkdir(parents=True, exist_ok=True)
        for old in dest.glob("*.whl"):
            old.unlink()
        for w in sorted(Path(tmp).glob("*.whl")):
            shutil.copy2(w, dest / w.name)
    return True


def compiled_modules(plat: str) -> dict[str, Path]:
    """The core's compiled modules (``core/ple/**/*.c``, built by ``make setup``) that this Python
    imports, by module name, when it can serve the zip of ``plat``: the same platform and
    Blender's Python 3.11. Empty otherwise (another platform's zip; a module whose optional build
    failed is left out with a warning): the core then runs its numpy form of the same
    computation, about 9× slower on the checks of unclean hubs."""
    import importlib.machinery
    import importlib.util

    if plat != this_platform() or sys.version_info[:2] != (3, 11):
        return {}
    found = {}
    for c in sorted((ROOT / "core" / "ple").rglob("*.c")):
        name = ".".join(c.relative_to(ROOT / "core").with_suffix("").parts)
        spec = importlib.util.find_spec(name)
        if spec is None or not str(spec.origin).endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)):
            print(f"warning: {name} is not built; the {plat} zip runs its numpy form", file=sys.stderr)
            continue
        found[name] = Path(spec.origin)
    return found


def stage(dest: Path, wheels: list[Path], plat: str, compiled: dict[str, Path] | None = None) -> dict:
    """Copy manifest, add-on, vendored core and presets into ``dest``, and ``wheels`` (listed in
    the staged manifest with ``platforms = [plat]``; none: a pure-Python package for any
    platform) and the ``compiled`` modules of ``compiled_modules`` beside their sources in the
    vendored core; returns the manifest."""
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    dest.mkdir(parents=True, exist_ok=True)
    text = (ROOT / "blender_manifest.toml").read_text()
    if wheels:  # top-level keys: they go before the first [table]
        (dest / "wheels").mkdir()
        for w in wheels:
            shutil.copy2(w, dest / "wheels" / w.name)
        head, sep, tail = text.partition("\n[")
        listed = ", ".join(f'"./wheels/{w.name}"' for w in wheels)
        text = f'{head}\nplatforms = ["{plat}"]\nwheels = [{listed}]\n{sep}{tail}'
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
    for name, so in (compiled or {}).items():  # imported relatively (``from . import _selfcheck``)
        shutil.copy2(so, vendor.joinpath(*name.split(".")[:-1]) / so.name)
    return manifest


def build(out_dir: Path, wheels: Path | None = WHEEL_DIR, plat: str | None = None) -> Path:
    """The zip of ``plat`` (default: this machine's) with its wheels from the folder ``wheels``,
    ``ple-<version>-<plat>.zip`` in ``out_dir``; with ``wheels`` None the pure-Python
    ``ple-<version>.zip``."""
    tool = blender_ext_tool()
    plat = plat or this_platform()
    bundled = wheels_for(plat, wheels) if wheels is not None else []
    with tempfile.TemporaryDirectory(prefix="ple-ext-") as tmp:
        src = Path(tmp) / "ple"
        manifest = stage(src, bundled, plat, compiled_modules(plat) if bundled else None)
        out_dir.mkdir(parents=True, exist_ok=True)
        suffix = f"-{plat}" if bundled else ""
        zip_path = out_dir / f"{manifest['id']}-{manifest['version']}{suffix}.zip"
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
    parser.add_argument("--platform", default="this", choices=["this", "all", *PLATFORMS],
                        help="whose zip is built (default: this machine's; all: one zip per platform)")
    parser.add_argument("--no-wheels", action="store_true",
                        help=f"bundle no wheels ({', '.join(WHEELS)} must then be in Blender's Python)")
    parser.add_argument("--fetch-wheels", action="store_true",
                        help="only download every platform's wheels into --wheels (the network; exit 1 if it cannot)")
    args = parser.parse_args(argv)
    if args.fetch_wheels:
        return 0 if fetch_wheels(Path(args.wheels)) else 1
    if args.no_wheels:
        print(build(Path(args.out), wheels=None))
        return 0
    plats = list(PLATFORMS) if args.platform == "all" else [None if args.platform == "this" else args.platform]
    for plat in plats:
        print(build(Path(args.out), Path(args.wheels), plat))
    return 0


if __name__ == "__main__":
    sys.exit(main())
