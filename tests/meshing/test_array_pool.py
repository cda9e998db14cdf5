"""``ArrayPool``: the memory of streamed boxes reused from encoded boxes to the next ones, and a
stream through it writes what a stream of fresh arrays writes."""

import os
import sys

import numpy as np
import pytest
from ple.bench.curved import curved_lattice
from ple.io.export import RecordPool, stl_chunk
from ple.meshing.tessellate import ArrayPool, iter_triangles, output_grid


def test_buffers_are_reused_by_size():
    pool = ArrayPool()
    a = pool.take((1000, 3), float)
    b = pool.take((500, 3), np.int32)
    assert a.shape == (1000, 3) and a.dtype == float and b.shape == (500, 3) and b.dtype == np.int32
    a[:] = 1.0
    b[:] = 7
    base_a = a.base
    while base_a.base is not None:
        base_a = base_a.base
    pool.give(a, b, np.zeros(3))  # arrays not from the pool are ignored
    c = pool.take((400, 3), np.int32)  # the smaller buffer fits: taken, not the larger
    assert np.shares_memory(c, b) and not np.shares_memory(c, a)
    d = pool.take((999, 3), float)
    assert np.shares_memory(d, a)
    e = pool.take((2000, 3), float)  # none left: a fresh one
    assert not np.shares_memory(e, a) and not np.shares_memory(e, b)
    pool.give(c, d, e)
    big = pool.take((5000, 3), float)  # larger than any: the largest is dropped for a new one
    assert big.shape == (5000, 3) and not any(np.shares_memory(big, x) for x in (c, d, e))
    assert base_a.dtype == np.uint8


def test_fresh_buffers_have_room_for_slightly_larger_boxes():
    """A fresh buffer is POOL_HEADROOM larger than asked: the next box, a few per cent larger,
    reuses it instead of mapping a fresh one; a box beyond the headroom does not."""
    from ple.meshing.tessellate import POOL_HEADROOM

    pool = ArrayPool()
    a = pool.take((1000, 3), float)
    pool.give(a)
    b = pool.take((1000 + int(1000 * POOL_HEADROOM), 3), float)
    assert np.shares_memory(a, b)
    pool.give(b)
    c = pool.take((1000 + int(1000 * POOL_HEADROOM) + 1, 3), float)
    assert not np.shares_memory(a, c)


FAULTS = """
import json, resource, sys
import numpy as np
from ple.meshing.tessellate import _keep_freed_memory
np.core.multiarray._set_madvise_hugepage(False)  # count 4 KiB pages
if sys.argv[1] == "1":
    _keep_freed_memory()
out = []
for _ in range(4):  # three 20 MB arrays alive at once, then freed: glibc trims them by default
    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    arrays = [np.ones((20 << 20) // 8) for _ in range(3)]
    del arrays
    out.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
print(json.dumps(out))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_template_processes_reuse_freed_memory():
    """In a template process (``_keep_freed_memory``), arrays freed by one round are the next
    round's memory: no fresh pages after the first round, where glibc's defaults (a fresh
    interpreter's) map and touch a large part of them again."""
    import json
    import subprocess

    got = {keep: json.loads(subprocess.run([sys.executable, "-c", FAULTS, str(int(keep))], check=True,
                                           capture_output=True, text=True).stdout) for keep in (False, True)}
    pages = 3 * (20 << 20) // 4096
    assert all(f > pages // 2 for f in got[False][1:]), got  # the default: fresh pages every round
    assert got[True][0] > pages // 2 and max(got[True][1:]) < pages // 50, got


def test_pooled_stream_writes_the_same_records():
    """Streamed boxes encoded as they come (pooled arrays, 1 and 2 workers) give the records of
    boxes assembled into fresh arrays and encoded afterwards."""
    lat = curved_lattice(7)
    grid = output_grid(lat)
    fresh = b"".join(stl_chunk(c, grid).tobytes() for c in iter_triangles(lat, None, "refined", 1, max_groups=30))
    for workers in (1, 2):
        records = RecordPool()
        got = []
        for rec in iter_triangles(lat, None, "refined", 1, max_groups=30, workers=workers,
                                  encode=lambda c, pool=records: stl_chunk(c, grid, pool)):
            got.append(rec.tobytes())
            records.give(rec)
        assert len(got) > 3 and b"".join(got) == fresh


def test_preparation_runs_a_bounded_way_ahead():
    """``_ahead``: futures in order, each submitted ``lookahead`` items before it is handed on;
    what is not handed on when the consumer stops is cancelled."""
    from concurrent.futures import ThreadPoolExecutor

    from ple.meshing.tessellate import _ahead

    started = []

    def work(b):
        started.append(b)
        return b * b

    with ThreadPoolExecutor(max_workers=1) as pool:
        gen = _ahead(pool, work, 20, 3)
        first = next(gen)
        assert first.result() == 0
        got = [first.result()] + [next(gen).result() for _ in range(4)]
        assert got == [0, 1, 4, 9, 16]
        gen.close()  # the consumer stops: the rest is not prepared
    assert len(started) <= 5 + 3 + 1 and started == sorted(started)
    with ThreadPoolExecutor(max_workers=1) as pool:
        assert [f.result() for f in _ahead(pool, work, 7, 2)] == [b * b for b in range(7)]


@pytest.mark.skipif(not os.path.exists("/proc/self/smaps"), reason="Linux's /proc/self/smaps")
def test_fresh_buffers_are_mapped_in_small_pages():
    """A large fresh pooled buffer is its own mapping advised against huge pages (the kernel's
    VmFlags ``nh``), writable, reused through ``give`` like any other, and unmapped once unused."""
    from ple.meshing.tessellate import POOL_MAP_MIN

    pool = ArrayPool()
    a = pool.take((POOL_MAP_MIN,), np.float64)
    a[:] = 2.5
    addr = a.__array_interface__["data"][0]

    def flags_at(address):
        lo = None
        for line in open("/proc/self/smaps"):
            head = line.split()
            if "-" in head[0] and ":" not in head[0]:
                s, e = (int(x, 16) for x in head[0].split("-"))
                lo = s <= address < e
            elif lo and line.startswith("VmFlags:"):
                return line.split()[1:]
        return None

    assert "nh" in flags_at(addr)
    pool.give(a)
    b = pool.take((POOL_MAP_MIN // 2,), np.float64)  # the same buffer again
    assert b.__array_interface__["data"][0] == addr and (b == 2.5).all()
    small = pool.take((10,), np.float64)  # small buffers: plain numpy memory
    assert small.base is not None
    del a, b
    pool._free.clear()
    assert flags_at(addr) is None or "nh" not in flags_at(addr)  # unmapped
