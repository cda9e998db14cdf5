"""``make docs``: the API reference from docstrings, the preset gallery with rendered
thumbnails, and the concept pictures — all produced by the project itself.

Pictures are rendered by ``tools/render_mesh.py`` (headless Blender Workbench) in a
subprocess; the meshes and curves it draws come from the core. A picture is re-rendered
only when its source (preset file) is newer than it.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import subprocess
import sys

from ple.io.files import atomic_write_text
from ple.meshing.preview import balls_beams_mesh
from ple.program.presets import preset_description, preset_names, preset_path
from ple.program.sources import load_lattice

from tools.docs_pictures import build_pictures
from tools.render import DOCS, ROOT, render

THUMBS = ROOT / "presets" / "thumbnails"
API_LAYERS = ["algebra", "model", "queries", "filters", "clg", "measure", "meshing", "io", "program", "app"]
THUMB_MAX_GROUPS = 64_000  # a thumbnail of a larger lattice shows a corner region of it


def api_modules() -> list[str]:
    """Every public module of the library layers, layer by layer (``algebra.similarity``, …)."""
    names = []
    for layer in API_LAYERS:
        pkg = importlib.import_module(f"ple.{layer}")
        names += [f"{layer}.{m.name}" for m in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name)
                  if not m.name.startswith("_")]  # private (the compiled STL encoder exists only where built)
    return names


def api_reference() -> str:
    """Markdown reference of the public classes and functions of the core modules."""
    out = ["# Program API reference", "",
           "Generated from the docstrings by `make docs` (`python -m tools.docs_build`).", ""]
    for name in api_modules():
        mod = importlib.import_module(f"ple.{name}")
        out += [f"## `ple.{name}`", "", inspect.cleandoc(mod.__doc__ or "").split("\n\n")[0], ""]
        for attr, obj in vars(mod).items():
            if attr.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
                continue
            if inspect.isclass(obj) or inspect.isfunction(obj):
                out += _entry(attr, obj)
    return "\n".join(out) + "\n"


def _entry(name: str, obj) -> list[str]:
    try:
        sig = str(inspect.signature(obj)).replace("'", "")
    except (TypeError, ValueError):
        sig = "(…)"
    kind = "class" if inspect.isclass(obj) else "def"
    doc = inspect.cleandoc(obj.__doc__ or "")
    lines = [f"### {kind} `{name}{sig}`", ""]
    if doc:
        lines += [doc, ""]
    if inspect.isclass(obj):
        for attr, member in vars(obj).items():
            if attr.startswith("_") or not (inspect.isfunction(member) or isinstance(member, (property, staticmethod))):
                continue
            fn = member.fget if isinstance(member, property) else getattr(member, "__func__", member)
            mdoc = inspect.cleandoc(fn.__doc__ or "").split("\n\n")[0]
            try:
                msig = "" if isinstance(member, property) else str(inspect.signature(fn)).replace("'", "")
            except (TypeError, ValueError):
                msig = "(…)"
            lines.append(f"- `{attr}{msig}` — {mdoc}" if mdoc else f"- `{attr}{msig}`")
        lines.append("")
    return lines


def thumbnail_region(lat) -> str:
    """The whole lattice, or a corner of it with at most THUMB_MAX_GROUPS groups (the
    largest direction is cut first)."""
    counts = list(lat.counts)
    while counts[0] * counts[1] * counts[2] > THUMB_MAX_GROUPS:
        big = counts.index(max(counts))
        counts[big] = max(1, int(counts[big] * 0.9))
    return ",".join(f"0:{c}" for c in counts)


def preset_preview(name: str):
    """The preview mesh of a preset's thumbnail (its filter applied where it has one)."""

    lat = load_lattice(name)
    region = thumbnail_region(lat)
    ev = lat.evaluate(region)
    return balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes, beam_scale=0.6), region


def build_thumbnails(force: bool = False) -> list[str]:
    """Render stale preset thumbnails into ``presets/thumbnails``; returns the names rendered."""
    done = []
    for name in preset_names():
        png = THUMBS / f"{name}.png"
        src = preset_path(name)
        if not force and png.is_file() and png.stat().st_mtime >= src.stat().st_mtime:
            continue
        mesh, _ = preset_preview(name)
        render(png, [mesh], size="360x270")
        done.append(name)
        print(f"  thumbnail {png.relative_to(ROOT)}", flush=True)
    return done


def presets_page() -> str:
    out = ["# Preset library", "", "`ple presets` lists them; load one by name anywhere a LATTICE is expected.",
           "Thumbnails of lattices beyond 64,000 node-groups show a corner region.", "",
           "| preset | purpose | counts | picture |", "|---|---|---|---|"]
    for name in preset_names():
        lat = load_lattice(name)
        counts = " × ".join(str(c) for c in lat.counts)
        pic = f"![{name}](../presets/thumbnails/{name}.png)" if (THUMBS / f"{name}.png").is_file() else ""
        out.append(f"| `{name}` | {preset_description(name)} | {counts} | {pic} |")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    atomic_write_text(DOCS / "api.md", api_reference())
    print(f"wrote {DOCS / 'api.md'}")
    if "--no-render" not in argv:
        build_thumbnails(force="--force" in argv)
        build_pictures(force="--force" in argv)
        rig_png = DOCS / "img" / "addon_rig.png"
        if "--force" in argv or not rig_png.is_file():  # the add-on guide's picture of a rig
            subprocess.run([sys.executable, "-m", "tools.render_blender", "--out", str(rig_png)], cwd=ROOT,
                           check=True)
    atomic_write_text(DOCS / "presets.md", presets_page())
    print(f"wrote {DOCS / 'presets.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
