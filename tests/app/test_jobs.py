"""Partitioned jobs on Dask (issue 17): a scheduler and two workers started as separate processes
on 127.0.0.1 give byte-identical parts to the embedded local cluster and to the single-process
path; a worker killed mid-job changes nothing; a re-run recomputes nothing that was complete."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from dask.distributed import Client
from daskcluster import dask_cluster, in_flight, kill_when
from ple.app.batch import plan
from ple.app.cluster import run_job
from ple.app.jobs import (
    assemble_slices,
    assemble_stl,
    count_job,
    count_totals,
    filter_job,
    load_filter_parts,
    mesh_job,
    slice_job,
    sweep_job,
)
from ple.cli.main import main
from ple.errors import PleError
from ple.filters.ir import filter_to_dict
from ple.filters.lil import lil
from ple.filters.stencil import Stencil
from ple.meshing.tessellate import tessellate
from ple.program.sources import load_lattice


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    with dask_cluster(tmp_path_factory.mktemp("dask")) as running:
        yield running


def _hashes(folder: Path) -> dict:
    manifest = json.loads((folder / "manifest.json").read_text())
    return {name: e["sha256"] for name, e in manifest["parts"].items()}


def test_mesh_parts_are_identical_on_every_path_and_close_up(tmp_path, cluster):
    address, _ = cluster
    job = mesh_job("fig6_3", [], "cnt", region="0:4,0:5,0:6", box_groups=24)
    assert len(job.parts) > 3
    sync = run_job(job, str(tmp_path / "sync"), "sync", progress=False)
    local = run_job(job, str(tmp_path / "local"), "local", workers=2, progress=False)
    remote = run_job(job, str(tmp_path / "remote"), address, progress=False)
    assert sync["written"] == local["written"] == remote["written"] == len(job.parts)
    h = _hashes(tmp_path / "sync")
    assert h == _hashes(tmp_path / "local") == _hashes(tmp_path / "remote")
    n = assemble_stl(str(tmp_path / "remote"), tmp_path / "all.stl")
    import trimesh

    mesh = trimesh.load(tmp_path / "all.stl")
    ref = tessellate(load_lattice("fig6_3"), "0:4,0:5,0:6", "cnt")
    assert n == len(ref.faces) and mesh.is_watertight and np.isclose(mesh.volume, ref.volume, rtol=1e-6)
    again = run_job(job, str(tmp_path / "remote"), address, progress=False)  # resume: nothing recomputed
    assert again["written"] == 0 and again["skipped"] == len(job.parts)
    (tmp_path / "remote" / job.parts[1].name).write_bytes(b"damaged")
    again = run_job(job, str(tmp_path / "remote"), address, progress=False)
    assert again["written"] == 1 and _hashes(tmp_path / "remote") == h


def test_a_killed_worker_loses_nothing(tmp_path, cluster):
    address, procs = cluster
    job = mesh_job("octet", ["n=3"], "refined", levels=2, box_groups=4)  # 9 parts of a few hundred ms
    out = tmp_path / "killed"
    result = {}
    thread = threading.Thread(target=lambda: result.update(run_job(job, str(out), address, progress=False)))
    thread.start()

    def some_parts_done_and_w1_busy() -> bool:  # the killed worker has a part in flight
        manifest = out / "manifest.json"
        return (manifest.is_file() and bool(json.loads(manifest.read_text())["parts"])
                and bool(in_flight(client)["w1"]))

    with Client(address, timeout=30) as client:
        killed = kill_when(procs[2], some_parts_done_and_w1_busy)  # one worker dies in the middle of the job
    thread.join(timeout=600)
    assert result["written"] == len(job.parts) and not result["failed"]
    assert not list(out.glob("*.tmp-*"))  # no half-written part
    assert any((out / name).stat().st_mtime > killed for name in _hashes(out))  # the job went on after the kill
    ref = run_job(job, str(tmp_path / "ref"), "sync", progress=False)
    assert ref["written"] == len(job.parts) and _hashes(out) == _hashes(tmp_path / "ref")


def test_sweep_and_filter_jobs(tmp_path):
    _, variants = plan("cubic", ["n=0,2,3"], "stl")
    job = sweep_job("cubic", variants, "cnt", "stl")
    res = run_job(job, str(tmp_path / "sweep"), "local", workers=2, progress=False)
    assert res["written"] == 2 and list(res["failed"]) == ["cubic__n-0.stl"]  # reported by name, others written
    assert "count" in res["failed"]["cubic__n-0.stl"]["error"]
    lat = load_lattice("cubic", ["n=7"]).with_filter(Stencil.named("faces", 3))
    job = filter_job("cubic", ["n=7"], None, 20, filter_to_dict(lat.filter))
    run_job(job, str(tmp_path / "filter"), "sync", progress=False)
    ev, want = load_filter_parts(str(tmp_path / "filter")), lat.evaluate()
    assert np.array_equal(ev.node_index, want.node_index) and np.array_equal(ev.beam_index, want.beam_index)
    assert np.array_equal(ev.center[ev.beam_nodes], want.center[want.beam_nodes])


def test_cli_doors_and_bad_input(tmp_path, capsys, monkeypatch):
    assert main(["mesh", "cubic", "--param", "n=4", "--style", "cnt", "--parts", str(tmp_path / "p"),
                 "--scheduler", "sync", "--box-groups", "16", "--out", str(tmp_path / "m.stl")]) == 0
    assert main(["assemble", str(tmp_path / "p"), "--out", str(tmp_path / "m2.stl")]) == 0
    assert (tmp_path / "m.stl").read_bytes() == (tmp_path / "m2.stl").read_bytes()
    lil = ["lil", "cubic", "--param", "n=9", "--coarse", "lil_regular_coarse", "--stencil", "checker:2"]
    assert main([*lil, "--parts", str(tmp_path / "l"), "--scheduler", "sync", "--slab-groups", "50"]) == 0
    assert main([*lil, "--out", str(tmp_path / "l.npz")]) == 0
    assert main(["assemble", str(tmp_path / "l"), "--out", str(tmp_path / "l2.npz")]) == 0
    with np.load(tmp_path / "l.npz") as a, np.load(tmp_path / "l2.npz") as b:
        assert 0 < len(a["node_index"]) and all(np.array_equal(a[k], b[k]) for k in a.files)
    monkeypatch.setattr("ple.app.cluster.CONNECT_TIMEOUT", 0.5)  # nothing listens on port 9: no need to retry for 5 s
    t0 = time.monotonic()
    assert main(["mesh", "cubic", "--parts", str(tmp_path / "x"), "--scheduler", "tcp://127.0.0.1:9"]) == 2
    assert time.monotonic() - t0 < 60 and "cannot reach the scheduler" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    with pytest.raises(PleError, match="is a file"):
        run_job(mesh_job("cubic", [], "cnt"), str(tmp_path / "file"), "sync")
    with pytest.raises(PleError, match="another job"):
        run_job(mesh_job("cubic", ["n=3"], "cnt"), str(tmp_path / "p"), "sync")


def _files(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_slice_parts_assemble_to_the_one_process_slices(tmp_path, cluster):
    address, _ = cluster
    flags = ["octet", "--param", "n=2", "--layer", "0.1", "--pixel", "0.04"]
    assert main(["slice", *flags, "--out", str(tmp_path / "one")]) == 0  # the one-process path
    one = _files(tmp_path / "one")
    assert len(one) > 10
    lat = load_lattice("octet", ["n=2"])
    job = slice_job("octet", ["n=2"], 0.1, 0.04, lat.bounds(), layers_per_part=6)
    assert len(job.parts) > 2
    run_job(job, str(tmp_path / "sync"), "sync", progress=False)
    remote = run_job(job, str(tmp_path / "remote"), address, progress=False)
    assert remote["written"] == len(job.parts) and _hashes(tmp_path / "sync") == _hashes(tmp_path / "remote")
    assemble_slices(str(tmp_path / "remote"), tmp_path / "two")
    assert _files(tmp_path / "two") == one  # every PNG and the manifest, byte for byte
    again = run_job(job, str(tmp_path / "remote"), address, progress=False)  # resume: nothing recomputed
    assert again["written"] == 0 and again["skipped"] == len(job.parts)
    (tmp_path / "remote" / job.parts[-1].name).unlink()
    again = run_job(job, str(tmp_path / "remote"), address, progress=False)
    assert again["written"] == 1 and _hashes(tmp_path / "remote") == _hashes(tmp_path / "sync")
    # the CLI door: --parts on the embedded cluster, assembled into --out
    assert main(["slice", *flags, "--parts", str(tmp_path / "cli"), "--workers", "2", "--layers-per-part", "5",
                 "--out", str(tmp_path / "three")]) == 0
    assert _files(tmp_path / "three") == one
    assert main(["assemble", str(tmp_path / "cli"), "--out", str(tmp_path / "four")]) == 0
    assert _files(tmp_path / "four") == one


@pytest.mark.parametrize("preset, params, region", [("octet", ["n=4"], "1:4,0:4,1:4"), ("fig6_3", [], "0:7,2:9,3:12"),
                                                    ("thesis_regular", ["n=9"], None)])
def test_counts_equal_the_evaluation(tmp_path, preset, params, region):
    """Kept nodes and beams counted slab by slab (halo masks) against the full evaluation's arrays."""
    lat = load_lattice(preset, params)
    lats = [lat.with_filter(Stencil.named("faces", 3)),
            lil(lat, load_lattice("lil_regular_coarse", {"span": 8.0}))]
    for n, filtered in enumerate(lats):
        job = count_job(preset, params, region, 7, filter_to_dict(filtered.filter))
        assert len(job.parts) > 3
        run_job(job, str(tmp_path / f"c{n}"), "sync", progress=False)
        ev = filtered.evaluate(region)
        assert count_totals(str(tmp_path / f"c{n}")) == {"nodes": len(ev.node_index), "beams": len(ev.beam_index),
                                                         "parts": len(job.parts)}


def test_lil_count_cli_on_a_real_cluster(tmp_path, cluster, capsys):
    address, _ = cluster
    lil_args = ["lil", "thesis_regular", "--param", "n=12", "--coarse", "lil_regular_coarse:span=11"]
    assert main([*lil_args, "--out", str(tmp_path / "all.npz")]) == 0
    with np.load(tmp_path / "all.npz") as z:
        nodes, beams = len(z["node_index"]), len(z["beam_index"])
    capsys.readouterr()
    assert main([*lil_args, "--count", "--parts", str(tmp_path / "p"), "--scheduler", address,
                 "--slab-groups", "100"]) == 0
    out = capsys.readouterr().out
    assert f"kept: {nodes:,} nodes of {2 * 12**3:,}" in out and f"{beams:,} beams of" in out
    assert main(["assemble", str(tmp_path / "p")]) == 0
    assert f"kept: {nodes:,} nodes, {beams:,} beams" in capsys.readouterr().out
    assert main([*lil_args, "--count"]) == 2 and "give --parts" in capsys.readouterr().err


def test_parts_of_an_unclean_lattice_carry_its_unions(tmp_path):
    from ple.app.pipeline import MeshRequest, write_mesh

    name, params = "becots_annulus", ["nu=2"]  # every hub is unclean (as at its defaults, 8 rows of 36)
    job = mesh_job(name, params, "cnt", box_groups=1)
    assert "united with manifold3d" in job.settings["unclean"] and len(job.parts) == 1
    assert run_job(job, str(tmp_path / "parts"), "sync", progress=False)["written"] == 1
    n = assemble_stl(str(tmp_path / "parts"), tmp_path / "all.stl")
    single = write_mesh(MeshRequest(load_lattice(name, params), style="cnt"), tmp_path / "single.stl")
    assert n == single
    assert (tmp_path / "all.stl").read_bytes()[80:] == (tmp_path / "single.stl").read_bytes()[80:]
    import trimesh

    mesh = trimesh.load(tmp_path / "all.stl")
    ref = tessellate(load_lattice(name, params), None, "cnt")
    assert len(ref.metadata["ple_unclean"].nodes) == 2 * 36
    assert mesh.is_watertight and np.isclose(mesh.volume, ref.volume, rtol=1e-5)
    clean = mesh_job("octet", ["n=2"], "cnt", box_groups=1)  # a clean lattice keeps its boxes
    assert clean.settings["unclean"] is None and len(clean.parts) == 8
