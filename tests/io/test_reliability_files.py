"""Outputs never destroy (issue 20, docs/reliability.md): output-folder markers, symlinks,
devices and FIFOs, refused destinations, temporaries on signals and after SIGKILL."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from ple.cli.main import main
from ple.errors import PleError
from ple.io.files import MARKER, TMP_TAG, atomic_path, atomic_write_text, read_marker, remove_stale_temporaries
from ple.program.sources import load_lattice
from reliability_helpers import CORE, assert_clean_failure, ple


def run(*args) -> int:
    return main([str(a) for a in args])


def _user_folder(path: Path, manifest: str) -> dict:
    path.mkdir()
    (path / "manifest.json").write_text(manifest)
    (path / "notes.txt").write_text("my notes")
    return {p.name: p.read_bytes() for p in path.iterdir()}


def _tree(path: Path) -> dict:
    return {p.name: p.read_bytes() for p in path.iterdir()}


@pytest.mark.parametrize("command", ["filter", "lil"])
@pytest.mark.parametrize("manifest", ["{}", json.dumps({"format": "ple-chunks/1", "chunks": []}),
                                      json.dumps({"format": "ple-batch/1", "outputs": []})])
def test_a_folder_pls_did_not_write_is_never_deleted(tmp_path, command, manifest, capsys):
    out = tmp_path / "mine"
    before = _user_folder(out, manifest)
    extra = ["--stencil", "edges:2"] if command == "filter" else ["--coarse", "cubic:n=2,cell=5"]
    assert run(command, "cubic", *extra, "--out", out) == 2
    assert "not touching it" in capsys.readouterr().err
    assert _tree(out) == before


def test_a_chunk_folder_written_by_filter_is_replaced_and_marked(tmp_path):
    out = tmp_path / "chunks"
    assert run("filter", "cubic", "--stencil", "edges:2", "--out", out) == 0
    assert read_marker(out) == {"kind": "ple-chunks", "version": 1, "command": "ple filter"}
    assert run("filter", "cubic", "--stencil", "corners:2", "--out", out) == 0
    assert json.loads((out / "manifest.json").read_text())["nodes"] == 125  # corners of period 2 in 10^3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chunks"]  # no temporaries, no trash


def test_an_empty_folder_is_used(tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    assert run("filter", "cubic", "--stencil", "edges:2", "--out", out) == 0
    assert (out / MARKER).is_file()


def test_a_batch_folder_is_not_a_chunk_folder(tmp_path):
    out = tmp_path / "b"
    assert run("batch", "cubic", "--param", "n=2", "--style", "balls-beams", "--out", out, "--jobs", "1") == 0
    before = _tree(out)
    assert run("filter", "cubic", "--stencil", "edges:2", "--out", out) == 2
    assert _tree(out) == before


def test_batch_refuses_a_user_folder_and_a_file(tmp_path, capsys):
    mine = tmp_path / "mine"
    before = _user_folder(mine, '{"my": "data"}')
    assert run("batch", "cubic", "--param", "n=2", "--out", mine) == 2
    assert _tree(mine) == before
    f = tmp_path / "file"
    f.write_text("keep")
    assert run("batch", "cubic", "--param", "n=2", "--out", f) == 2
    assert f.read_text() == "keep"
    assert "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize("entry", [7, None, {"nofile": 1}, {"file": "../x.stl"}])
def test_a_bad_batch_manifest_entry_is_a_clean_error(tmp_path, entry, capsys):
    out = tmp_path / "b"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({"format": "ple-batch/1", "outputs": [entry]}))
    assert run("batch", "cubic", "--param", "n=2", "--out", out) == 2
    assert "outputs[0]" in capsys.readouterr().err


def test_symlink_is_followed_not_replaced(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    assert run("ir", "cubic", "--out", link) == 0
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert json.loads(target.read_text())["format"] == "ple-lattice/1"


def test_fifo_is_written_in_place(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    assert run("ir", "cubic", "--out", fifo) == 0
    reader.join(30)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert json.loads(got[0])["format"] == "ple-lattice/1"


@pytest.mark.skipif(os.geteuid() != 0, reason="making a character device needs root")
def test_character_device_is_written_in_place_never_replaced(tmp_path):
    dev = tmp_path / "null"
    os.mknod(dev, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # a private /dev/null
    assert run("ir", "cubic", "--out", dev) == 0
    assert run("eval", "cubic", "--out", dev) == 2  # eval wants a .npz name
    assert stat.S_ISCHR(os.stat(dev).st_mode)
    assert run("mesh", "cubic", "--param", "n=2", "--out", str(dev) + ".stl") == 0  # a new regular file


def test_folder_and_unwritable_destinations_are_refused(tmp_path, capsys):
    (tmp_path / "d.json").mkdir()
    assert run("ir", "cubic", "--out", tmp_path / "d.json") == 2
    assert "is a folder" in capsys.readouterr().err
    assert run("ir", "cubic", "--out", "/proc/ple-test.json") == 2  # cannot create anything there
    assert "cannot write" in capsys.readouterr().err
    assert run("ir", "cubic", "--out", tmp_path / "no" / "x.json") == 2
    assert "does not exist" in capsys.readouterr().err


def test_error_leaves_destination_and_folder_as_they_were(tmp_path):
    dest = tmp_path / "x.json"
    dest.write_text("precious")
    with pytest.raises(RuntimeError):
        with atomic_path(dest) as tmp:
            tmp.write_text("half")
            raise RuntimeError
    assert dest.read_text() == "precious"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


def test_replaced_file_keeps_its_permissions(tmp_path):
    dest = tmp_path / "x.json"
    dest.write_text("old")
    dest.chmod(0o640)
    atomic_write_text(dest, "new")
    assert stat.S_IMODE(dest.stat().st_mode) == 0o640 and dest.read_text() == "new"


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    dead = _dead_pid()
    stale_file = tmp_path / f".big.stl{TMP_TAG}{dead}-abc.stl"
    stale_file.write_bytes(b"x" * 1000)
    stale_dir = tmp_path / f".out{TMP_TAG}{dead}-xyz"
    (stale_dir / "sub").mkdir(parents=True)
    live = tmp_path / f".other.stl{TMP_TAG}1-abc.stl"  # pid 1 is alive: not ours to remove
    live.write_text("busy")
    user = tmp_path / ".hidden-user-file"
    user.write_text("mine")
    # a temp of a temp (a child writing the temporary its live parent renames): the writer is the last tag
    nested_dead = tmp_path / f"..n.stl{TMP_TAG}{os.getpid()}-abc.stl{TMP_TAG}{dead}-def.stl"
    nested_live = tmp_path / f"..m.stl{TMP_TAG}{dead}-abc.stl{TMP_TAG}1-def.stl"
    nested_dead.write_text("x")
    nested_live.write_text("x")
    assert run("ir", "cubic", "--out", tmp_path / "x.json") == 0
    assert not stale_file.exists() and not stale_dir.exists() and not nested_dead.exists()
    assert live.exists() and user.exists() and nested_live.exists()
    assert remove_stale_temporaries(tmp_path) == []


def default_signals() -> None:
    """In the child before exec: SIGINT and SIGTERM at their defaults, whatever the test run
    inherited or set (an ignored SIGINT is inherited through exec, and Python then keeps it)."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)


def _start_big_write(tmp_path: Path, out: str):
    # long enough to be signalled mid-write (tens of millions of triangles), small enough that the
    # disk check (an upper bound of the STL's size) passes on a machine with a few GiB free
    proc = subprocess.Popen([sys.executable, "-m", "ple.cli", "mesh", "cubic", "--param", "n=40", "--levels", "2",
                             "--out", out],
                            cwd=tmp_path, env={**os.environ, "PYTHONPATH": CORE}, preexec_fn=default_signals,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for _ in range(600):  # until the temporary exists (the write has begun); not a timing assertion
        if any(TMP_TAG in p.name for p in tmp_path.iterdir()):
            return proc
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    proc.kill()
    raise AssertionError(f"the write did not start: {proc.communicate()}")


def _children(pid: int) -> set[int]:
    """Processes whose parent is ``pid`` (``/proc``)."""
    out = set()
    for d in Path("/proc").iterdir():
        try:
            if d.name.isdigit() and int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                out.add(int(d.name))
        except (OSError, ValueError, IndexError):
            pass
    return out


def _gone(pids: set[int], seconds: float = 10.0) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if not any(Path(f"/proc/{p}").exists() and "Z" not in (Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1]
                   .split()[0]) for p in pids):
            return True
        time.sleep(0.05)
    return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_signal_during_a_write_leaves_nothing(tmp_path, sig):
    (tmp_path / "big.stl").write_text("previous")
    proc = _start_big_write(tmp_path, "big.stl")
    helpers = _children(proc.pid)  # the hub-template processes of --workers (default: the cores)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, err
    assert "interrupted" in err and "Traceback" not in err and "Exception ignored" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.stl"]
    assert (tmp_path / "big.stl").read_text() == "previous"
    assert _gone(helpers)  # no orphan left behind


def test_sigkill_leftovers_are_removed_by_the_next_run(tmp_path):
    proc = _start_big_write(tmp_path, "big.stl")
    helpers = _children(proc.pid)
    proc.kill()
    proc.communicate(timeout=120)  # no template process keeps the command's output open
    assert _gone(helpers)
    assert any(TMP_TAG in p.name for p in tmp_path.iterdir())  # what SIGKILL leaves behind
    assert run("mesh", "cubic", "--param", "n=2", "--out", tmp_path / "small.stl") == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["small.stl"]


def test_interrupted_npz_write_is_quiet_and_leaves_nothing(tmp_path):
    script = f"""
import gc, numpy as np
from ple.io.files import save_npz
class Interrupt:
    def __array__(self, *a, **k):
        raise KeyboardInterrupt
try:
    save_npz({str(tmp_path / 'x.npz')!r}, {{"a": np.zeros(1000), "b": Interrupt()}})
except KeyboardInterrupt:
    pass
gc.collect()
"""
    res = subprocess.run([sys.executable, "-c", script], env={**os.environ, "PYTHONPATH": CORE},
                         capture_output=True, text=True)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert list(tmp_path.iterdir()) == []


def test_streamed_chunks_stop_before_the_disk_is_full(tmp_path, monkeypatch):
    import shutil

    from ple.filters.base import FilteredLattice
    from ple.filters.stencil import Stencil
    from ple.io import chunks as stream

    real = shutil.disk_usage
    calls = []

    def disk(path):  # plenty for the up-front bound, then nearly full while writing
        calls.append(path)
        return real(path)._replace(free=10**15 if len(calls) == 1 else stream.DISK_MARGIN // 2)

    monkeypatch.setattr(stream.shutil, "disk_usage", disk)
    flat = FilteredLattice(load_lattice("cubic"), Stencil(np.ones((1, 1, 1), bool)))
    with pytest.raises(PleError, match="nearly full after 0 chunks"):
        stream.stream_filter(flat, tmp_path / "out", slab_groups=100, progress=False)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(stream.shutil, "disk_usage", lambda p: real(p)._replace(free=10**6))
    with pytest.raises(PleError, match="could stream up to"):
        stream.stream_filter(flat, tmp_path / "out", progress=False)
    assert list(tmp_path.iterdir()) == []


def test_streaming_a_huge_lattice_is_refused_before_it_fills_the_disk(tmp_path, capsys):
    assert run("filter", "cubic", "--param", "n=10000", "--stencil", "edges", "--out", tmp_path / "c") == 2
    assert "could stream up to" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_subprocess_helper_reports_clean_failures(tmp_path):
    (tmp_path / "d.json").mkdir()
    assert_clean_failure(ple("ir", "cubic", "--out", tmp_path / "d.json"), "is a folder")
