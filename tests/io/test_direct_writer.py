"""Streamed STL through O_DIRECT (``ple.io.files.DirectWriter``): the file's bytes are those of
plain buffered writes for any sizes of writes and buffers, where the file system refuses
O_DIRECT at open or at a write, and an error leaves no file behind and no thread running."""

from __future__ import annotations

import errno
import os
import threading

import numpy as np
import pytest
from ple.errors import PleError
from ple.io import export, files


def chunks(rng, k=9):
    out = []
    for _ in range(k):
        v = rng.normal(size=(2000, 3))
        out.append((v, rng.integers(0, len(v), (int(rng.integers(1, 5000)), 3))))
    return out


def plain_stl(path, data, monkeypatch):
    with monkeypatch.context() as m:
        m.setattr(export, "direct_writer", lambda fh: None)
        export.write_stl(path, data, grid=2.0**-12)
    return path.read_bytes()


def writer_threads():
    return [t for t in threading.enumerate() if t.name == "ple-direct-writer"]


@pytest.mark.parametrize("sizes", [[0], [1], [4095], [4096], [4097], [5000, 3000, 1], [20_000] * 7, [4096 * 3] * 4])
@pytest.mark.parametrize("buffer", [4096, 3 * 4096])
def test_bytes_of_any_writes(tmp_path, sizes, buffer):
    rng = np.random.default_rng(len(sizes) + buffer)
    parts = [rng.integers(0, 256, n, dtype=np.uint8).tobytes() for n in sizes]
    path = tmp_path / "d.bin"
    path.write_bytes(b"")
    w = files.DirectWriter(path, buffer=buffer, buffers=2)
    for p in parts:
        w.write(p)
    assert w.close() == sum(sizes)
    assert path.read_bytes() == b"".join(parts)
    assert not writer_threads()


def test_stl_through_direct_writes_equals_buffered(tmp_path, monkeypatch):
    opened = []
    real = files.DirectWriter

    def spy(path, *a, **k):
        opened.append(path)
        return real(path, buffer=3 * 4096, buffers=2)

    monkeypatch.setattr(export, "DirectWriter", spy)
    data = chunks(np.random.default_rng(1))
    n = export.write_stl(tmp_path / "a.stl", data, grid=2.0**-12)
    assert opened  # this file system allows O_DIRECT (ext4, xfs, tmpfs of recent kernels)
    want = plain_stl(tmp_path / "b.stl", data, monkeypatch)
    got = (tmp_path / "a.stl").read_bytes()
    assert got == want and int.from_bytes(got[80:84], "little") == n
    assert not writer_threads()


def test_refused_at_open_writes_buffered(tmp_path, monkeypatch):
    real_open = os.open

    def no_direct(path, flags, *a):
        if flags & getattr(os, "O_DIRECT", 0):
            raise OSError(errno.EINVAL, "O_DIRECT refused")
        return real_open(path, flags, *a)

    monkeypatch.setattr(files.os, "open", no_direct)
    data = chunks(np.random.default_rng(2))
    export.write_stl(tmp_path / "a.stl", data, grid=2.0**-12)
    monkeypatch.undo()
    assert (tmp_path / "a.stl").read_bytes() == plain_stl(tmp_path / "b.stl", data, monkeypatch)


def test_refused_at_a_write_goes_on_buffered(tmp_path, monkeypatch):
    real_pwrite = os.pwrite
    direct_fds = set()
    real_open = os.open
    calls = {"n": 0}

    def track_open(path, flags, *a):
        fd = real_open(path, flags, *a)
        if flags & getattr(os, "O_DIRECT", 0):
            direct_fds.add(fd)
        return fd

    def pwrite(fd, data, offset):
        if fd in direct_fds:
            calls["n"] += 1
            if calls["n"] >= 2:  # the first direct write goes through, then O_DIRECT is refused
                raise OSError(errno.EINVAL, "refused")
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(files.os, "open", track_open)
    monkeypatch.setattr(files.os, "pwrite", pwrite)
    monkeypatch.setattr(files, "DIRECT_BUFFER", 3 * 4096)
    monkeypatch.setattr(export, "DirectWriter", lambda p: files.DirectWriter(p, buffer=3 * 4096, buffers=2))
    data = chunks(np.random.default_rng(3))
    export.write_stl(tmp_path / "a.stl", data, grid=2.0**-12)
    monkeypatch.undo()
    assert calls["n"] == 2
    assert (tmp_path / "a.stl").read_bytes() == plain_stl(tmp_path / "b.stl", data, monkeypatch)


def test_a_failed_write_leaves_nothing(tmp_path, monkeypatch):
    """The disk fills up during the stream: the error reaches the caller as a user error (one line
    naming the file), the destination keeps what it had, no temporary is left and the writer
    thread has ended."""
    real_pwrite = os.pwrite

    def full(fd, data, offset):
        if offset > 8192:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(files.os, "pwrite", full)
    monkeypatch.setattr(export, "DirectWriter", lambda p: files.DirectWriter(p, buffer=4096, buffers=2))
    dest = tmp_path / "a.stl"
    dest.write_bytes(b"the user's file")
    with pytest.raises(PleError, match="a.stl: cannot write .No space"):
        export.write_stl(dest, chunks(np.random.default_rng(4)), grid=2.0**-12)
    assert dest.read_bytes() == b"the user's file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.stl"]
    assert not writer_threads()


def test_an_error_upstream_stops_the_writer(tmp_path):
    def boxes():
        yield from chunks(np.random.default_rng(5), 3)
        raise ValueError("a bad box")

    with pytest.raises(ValueError, match="a bad box"):
        export.write_stl(tmp_path / "a.stl", boxes(), grid=2.0**-12)
    assert not (tmp_path / "a.stl").exists()
    assert not writer_threads()


def test_an_error_at_close_stops_the_writer(tmp_path, monkeypatch):
    real_pwrite = os.pwrite

    def full(fd, data, offset):
        if offset >= 4096:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(files.os, "pwrite", full)
    path = tmp_path / "d.bin"
    path.write_bytes(b"")
    w = files.DirectWriter(path, buffer=1 << 20, buffers=2)
    w.write(b"x" * 10_000)  # all of it still in the first buffer: the error comes at close
    with pytest.raises(OSError, match="No space"):
        w.close()
    assert not writer_threads()
