"""The docs are produced by the project: API reference, preset gallery, a real render."""

from __future__ import annotations

import importlib
import importlib.util
import re
from pathlib import Path

import numpy as np
from PIL import Image
from ple.meshing.preview import balls_beams_mesh
from ple.program.presets import preset_names
from ple.program.sources import load_lattice

from tools.docs_build import THUMBS, api_reference, presets_page, render


def test_api_reference_covers_the_program_api():
    text = api_reference()
    for needle in ("class `Lattice", "`set_u(self, count: int", "def `Swirl(angle, axis, point, factor) -> Similarity`",
                   "`between_frames",
                   "def `load_lattice"):
        assert needle in text


def test_presets_page_lists_every_preset():
    page = presets_page()
    for name in preset_names():
        assert f"`{name}`" in page


def test_render_produces_a_picture_of_the_lattice(tmp_path):
    ev = load_lattice("cubic", {"n": 2}).evaluate()
    png = tmp_path / "c.png"
    render(png, [balls_beams_mesh(ev.center, ev.radius, ev.beam_nodes)], size="160x120")
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert img.shape == (120, 160, 3)
    # the object is drawn: the picture is not a single flat background colour
    background = img[0, 0]
    assert (np.abs(img - background).sum(axis=2) > 30).mean() > 0.02


def test_every_preset_has_a_rendered_thumbnail():
    """make docs renders one per preset (re-rendered when the preset changes)."""
    for name in preset_names():
        png = THUMBS / f"{name}.png"
        assert png.is_file(), f"{name}: run make docs"
        img = np.asarray(Image.open(png).convert("RGB")).astype(int)
        assert (np.abs(img - img[0, 0]).sum(axis=2) > 30).mean() > 0.01, f"{name}: empty thumbnail"


def test_every_import_in_the_docs_resolves():
    """Code in README.md and docs/*.md follows the layered paths: each ``from ple… import`` line
    names existing modules and names."""
    root = Path(__file__).resolve().parents[2]
    pages = [root / "README.md", *sorted((root / "docs").glob("*.md"))]
    found = 0
    for page in pages:
        for mod, names in re.findall(r"^\s*from (ple[\w.]*) import ([\w, ]+)", page.read_text(), re.M):
            module = importlib.import_module(mod)
            for name in (n.strip().split(" as ")[0] for n in names.split(",")):
                assert hasattr(module, name) or importlib.util.find_spec(f"{mod}.{name}"), f"{page.name}: {mod}.{name}"
                found += 1
    assert found > 20
