"""Streaming filters over slabs: chunks on disk identical to the in-memory filtered evaluation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from lattices import KINDS, centre_on, random_lattice
from ple.app.progress import Progress
from ple.errors import PleError
from ple.filters.base import Filter, FilteredLattice
from ple.filters.implicit import ImplicitFilter, TPMSField
from ple.filters.lil import LiL
from ple.filters.stencil import Stencil
from ple.io.chunks import iter_chunks, load_chunks, read_manifest, stream_filter


def fine_with_far_beams(seed: int, kind: str):
    rng = np.random.default_rng(seed)
    fine = random_lattice(rng, [kind, *rng.choice(KINDS, 2)], (6, 5, 4), step=1.0, radius=0.15)
    # beams reaching two groups back and forth across slab boundaries in every direction
    for off in [(-1, 1, 1), (2, 0, -1), (-2, -1, 0), (1, 1, 1), (0, -2, 2)]:
        fine.add_beam(int(rng.integers(len(fine.nodes))), int(rng.integers(len(fine.nodes))), *off)
    coarse = random_lattice(rng, list(rng.choice(KINDS, 3)), (3, 3, 2), step=2.0, radius=0.45, nodes=1)
    centre_on(coarse, fine)
    return fine, coarse


def assert_same(a, b):
    for key, value in a.arrays().items():
        other = b.arrays()[key]
        assert value.shape == other.shape, key
        assert np.array_equal(value, other), key


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("slab", [1, 3, 7, 12, 40, 10**6])
def test_streamed_equals_in_memory(tmp_path, kind, slab):
    fine, coarse = fine_with_far_beams(KINDS.index(kind), kind)
    flt = Stencil(np.array([[[True, True, False]]])) | LiL(coarse)
    flat = FilteredLattice(fine, flt)
    manifest = stream_filter(flat, tmp_path / "out", slab_groups=slab, progress=False)
    whole = flat.evaluate()
    assert_same(load_chunks(tmp_path / "out"), whole)
    assert manifest["nodes"] == len(whole.node_index) and manifest["beams"] == len(whole.beam_index)
    assert 0 < len(whole.beam_index) < fine.beam_count()
    assert read_manifest(tmp_path / "out") == manifest


@pytest.mark.parametrize("slab", [2, 9, 10**6])
def test_streamed_region(tmp_path, slab):
    fine, coarse = fine_with_far_beams(11, "swirl")
    flat = FilteredLattice(fine, ImplicitFilter(TPMSField("gyroid", 3.0), 0.5))
    stream_filter(flat, tmp_path / "r", region="1:5,1:4,0:3", slab_groups=slab, progress=False)
    assert_same(load_chunks(tmp_path / "r"), flat.evaluate("1:5,1:4,0:3"))


def test_chunks_are_self_describing(tmp_path):
    fine, coarse = fine_with_far_beams(3, "screw")
    flat = FilteredLattice(fine, LiL(coarse))
    manifest = stream_filter(flat, tmp_path / "c", slab_groups=10, progress=False)
    offset = 0
    for entry, arrays in iter_chunks(tmp_path / "c"):
        assert entry["node_offset"] == offset and len(arrays["node_index"]) == entry["nodes"]
        # a beam is written once both of its nodes are known: rows never point past this chunk
        if len(arrays["beam_nodes"]):
            assert arrays["beam_nodes"].max() < offset + entry["nodes"]
        offset += entry["nodes"]
    assert offset == manifest["nodes"]
    assert json.loads((tmp_path / "c" / "manifest.json").read_text())["format"] == "ple-chunks/1"


class Exploding(Filter):
    def __init__(self):
        self.calls = 0

    def node_mask(self, lat, node_index, center, radius):
        self.calls += 1
        if self.calls == 3:
            raise PleError("boom")
        return np.ones(len(node_index), bool)


def test_no_partial_output(tmp_path):
    fine, _ = fine_with_far_beams(5, "rotation")
    with pytest.raises(PleError, match="boom"):
        stream_filter(FilteredLattice(fine, Exploding()), tmp_path / "x", slab_groups=5, progress=False)
    assert list(tmp_path.iterdir()) == []
    # an existing chunk directory is replaced whole; a foreign folder is refused
    stream_filter(FilteredLattice(fine, Stencil(np.ones((1, 1, 1), bool))), tmp_path / "x", progress=False)
    stream_filter(FilteredLattice(fine, Stencil(np.zeros((1, 1, 1), bool))), tmp_path / "x", progress=False)
    assert read_manifest(tmp_path / "x")["nodes"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x"]
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(PleError, match="not a ple-chunks output"):
        stream_filter(FilteredLattice(fine, Stencil(np.ones((1, 1, 1), bool))), tmp_path / "mine", progress=False)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"
    with pytest.raises(PleError):
        read_manifest(tmp_path / "mine")


def test_progress_bar_writes_to_a_terminal_only():
    class Term:
        def __init__(self, tty):
            self.text, self.tty = "", tty

        def isatty(self):
            return self.tty

        def write(self, s):
            self.text += s

        def flush(self):
            pass

    term, pipe = Term(True), Term(False)
    for stream in (term, pipe):
        bar = Progress(10, "filter", stream=stream)
        bar.update(10, "done")
        bar.close()
    assert "100.0%" in term.text and pipe.text == ""


def test_cli_filter_streams_chunks(tmp_path):
    from ple.cli.main import main
    from ple.program.sources import load_lattice

    out = tmp_path / "chunks"
    argv = ["filter", "bcc", "--param", "n=9", "--implicit", "gyroid:cell=4,level=0.6,sheet", "--stencil", "edges:3",
            "--out", str(out), "--slab-groups", "50"]
    assert main(argv) == 0
    flat = FilteredLattice(load_lattice("bcc", {"n": 9}),
                           Stencil.named("edges", 3) & ImplicitFilter(TPMSField("gyroid", 4.0), 0.6, "sheet"))
    assert_same(load_chunks(out), flat.evaluate())
    assert len(read_manifest(out)["chunks"]) > 5
    assert main(argv[:-2] + ["--out", str(tmp_path / "one.npz")]) == 0
    with np.load(tmp_path / "one.npz") as z:
        assert np.array_equal(z["beam_nodes"], flat.evaluate().beam_nodes)
