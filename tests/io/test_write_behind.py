"""Write-behind of streamed STL files (``ple.io.files.WriteBehind``): the kernel is asked to
write back every window in order and to drop a window's pages only after waiting for it; the
file's bytes are those of a plain write."""

from __future__ import annotations

import numpy as np
import pytest
from ple.io import export, files


@pytest.fixture(autouse=True)
def buffered(monkeypatch):
    """Write-behind serves buffered writes: files the O_DIRECT writer would take are kept from it."""
    monkeypatch.setattr(export, "direct_writer", lambda fh: None)


def chunks(rng, k=12):
    out = []
    for _ in range(k):
        v = rng.normal(size=(3000, 3))
        out.append((v, rng.integers(0, len(v), (4000, 3))))
    return out


def test_windows_in_order_and_dropped_after_waiting(tmp_path, monkeypatch):
    calls = []

    def sync(fd, start, n, flags):
        calls.append(("sync", start, n, flags))
        return 0

    def fadvise(fd, start, n, advice):
        calls.append(("drop", start, n, advice))

    monkeypatch.setattr(files, "_SYNC_RANGE", sync)
    monkeypatch.setattr(files.os, "posix_fadvise", fadvise, raising=False)
    monkeypatch.setattr(files, "WRITE_BEHIND", 500_000)
    data = chunks(np.random.default_rng(1))
    export.write_stl(tmp_path / "a.stl", data, grid=2.0**-12)
    monkeypatch.setattr(files, "_SYNC_RANGE", None)
    export.write_stl(tmp_path / "b.stl", data, grid=2.0**-12)
    assert (tmp_path / "a.stl").read_bytes() == (tmp_path / "b.stl").read_bytes()

    started = [(s, n) for kind, s, n, f in calls if kind == "sync" and f == files._SYNC_WRITE]
    assert len(started) >= 4
    assert started[0][0] == 84 and all(n >= 500_000 for _, n in started)
    assert all(a + n == b for (a, n), (b, _) in zip(started, started[1:]))  # after the header: no gap, no overlap
    assert started[-1][0] + started[-1][1] <= (tmp_path / "a.stl").stat().st_size
    dropped = [(s, n) for kind, s, n, _ in calls if kind == "drop"]
    assert dropped == started[:len(dropped)] and len(dropped) == len(started) - 1
    for s, n in dropped:  # waited for right before it is dropped
        i = calls.index(("drop", s, n, files.os.POSIX_FADV_DONTNEED))
        assert calls[i - 1] == ("sync", s, n, files._SYNC_WAIT)


def test_refused_range_falls_back_to_plain_writes(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(files, "_SYNC_RANGE", lambda *a: calls.append(a) or -1)
    monkeypatch.setattr(files, "WRITE_BEHIND", 100_000)
    data = chunks(np.random.default_rng(2), 5)
    n = export.write_stl(tmp_path / "a.stl", data)
    assert len(calls) == 1  # refused once, then left alone
    assert (tmp_path / "a.stl").stat().st_size == 84 + 50 * n


@pytest.mark.skipif(files._SYNC_RANGE is None, reason="no sync_file_range here")
def test_real_kernel_calls_keep_the_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(files, "WRITE_BEHIND", 1 << 20)
    data = chunks(np.random.default_rng(3), 20)
    export.write_stl(tmp_path / "a.stl", data, grid=2.0**-12)
    monkeypatch.setattr(files, "_SYNC_RANGE", None)
    export.write_stl(tmp_path / "b.stl", data, grid=2.0**-12)
    assert (tmp_path / "a.stl").read_bytes() == (tmp_path / "b.stl").read_bytes()
