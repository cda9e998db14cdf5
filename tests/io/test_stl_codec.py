"""The compiled STL encoder (``ple.io._stlcodec``) writes the numpy encoder's bytes, record for
record: snapped corners, dropped degenerate faces, float32 normals; and both agree with a plain
float64 computation of the same records."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from ple.io import export

pytestmark = pytest.mark.skipif(export._codec is None, reason="the compiled STL encoder was not built (no C compiler)")


def numpy_records(chunk, grid):
    keep = export._codec
    try:
        export._codec = None
        return export.stl_chunk(chunk, grid)
    finally:
        export._codec = keep


def hostile_mesh(rng, nv=600, nf=40_000):
    """Vertices over many scales with exact zeros, signed zeros, repeats; faces with repeated corners."""
    v = rng.normal(size=(nv, 3)) * 10.0 ** rng.uniform(-9, 3, (nv, 1))
    v[::7] = 0.0
    v[::11] *= -0.0
    v[5::13] = v[4::13][: len(v[5::13])]  # coinciding vertices under different ids
    f = rng.integers(0, nv, (nf, 3))
    f[::5, 1] = f[::5, 0]
    f[1::9, 2] = f[1::9, 1]
    return v, f


@pytest.mark.parametrize("grid", [None, 1e-3, 2.0**-20, 0.5])
@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_compiled_equals_numpy(grid, index):
    rng = np.random.default_rng(7)
    v, f = hostile_mesh(rng)
    got = export.stl_chunk((v, f.astype(index)), grid)
    want = numpy_records((v, f), grid)
    assert len(got) == len(want)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("grid", [None, 2.0**-20])
def test_pooled_buffers_hold_the_float32_vertices(grid):
    """From a pool, the records' buffer also holds the encoder's float32 vertices after the
    faces' records (any byte alignment of that tail): the same records, and a reused buffer
    with stale bytes changes nothing."""
    rng = np.random.default_rng(11)
    v, f = hostile_mesh(rng, 900, 3001)
    want = numpy_records((v, f), grid)
    pool = export.RecordPool()
    for _ in range(3):  # a fresh buffer, then the same one reused
        got = export.stl_chunk((v, f), grid, pool)
        assert got.tobytes() == want.tobytes()
        assert got.base is not None and got.base.nbytes >= 50 * len(f) + 12 * len(v)
        pool.give(got)
    raw = np.full(50 * len(f) + 12 * len(v) + 64, 255, np.uint8)
    for shift in range(4):  # the vertices' tail at every address modulo 4 (views, not copies)
        out = raw[shift:shift + 50 * len(f) + 12 * len(v) + 3]
        n = export._codec.encode(v, f, 0.0 if grid is None else grid, out)
        assert out[:50 * n].tobytes() == want.tobytes()
    small = np.zeros(50 * len(f) + 12 * len(v) - 1, np.uint8)  # no room: allocated inside, same records
    n = export._codec.encode(v, f, 0.0 if grid is None else grid, small)
    assert small[:50 * n].tobytes() == want.tobytes()


def test_records_against_float64():
    """Corners are the float32 of the snapped vertices, faces with two equal snapped corners are
    gone, normals are the unit cross products (float64 reference, float32 tolerance)."""
    rng = np.random.default_rng(3)
    v, f = hostile_mesh(rng, 300, 5000)
    g = 2.0**-10
    rec = export.stl_chunk((v, f), g)
    s = np.round(v / g) * g
    tri = s[f]
    same = np.zeros(len(f), bool)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        same |= np.all(tri[:, a] == tri[:, b], axis=1)
    tri = tri[~same]
    assert len(rec) == len(tri)
    assert np.array_equal(rec["vertices"], tri.astype(np.float32))
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ln = np.linalg.norm(n, axis=1)
    # float32 edges err by eps·|corner|: the normal's direction by about that over the area
    scale = np.abs(tri).max(axis=(1, 2))
    edges = np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1) + np.linalg.norm(tri[:, 2] - tri[:, 0], axis=1)
    tol = 16 * 2.0**-23 * scale * edges / np.where(ln > 0, ln, 1) + 1e-6
    ok = (ln > 0) & (tol < 0.1)
    assert ok.sum() > len(tri) // 2
    err = np.linalg.norm(rec["normal"][ok] - n[ok] / ln[ok, None], axis=1)
    assert np.all(err <= tol[ok])
    assert np.all(rec["attr"] == 0)


def test_whole_file_is_the_same(tmp_path):
    """write_stl with and without the compiled encoder: the same file, which trimesh reads."""
    box = trimesh.creation.icosphere(3)
    chunks = [(box.vertices + [i, 0, 0], box.faces) for i in range(3)]
    a, b = tmp_path / "a.stl", tmp_path / "b.stl"
    export.write_stl(a, chunks, grid=2.0**-16, workers=2)
    keep = export._codec
    try:
        export._codec = None
        export.write_stl(b, chunks, grid=2.0**-16, workers=2)
    finally:
        export._codec = keep
    assert a.read_bytes() == b.read_bytes()
    mesh = trimesh.load(a, process=True)
    assert len(mesh.faces) == 3 * len(box.faces) and mesh.is_watertight


def test_bad_arrays_are_refused():
    v = np.zeros((3, 3))
    out = np.empty(1, export.STL_RECORD)
    with pytest.raises(IndexError, match="out of range"):
        export._codec.encode(v, np.array([[0, 1, 3]], np.int64), 0.0, out)
    with pytest.raises(IndexError, match="out of range"):
        export._codec.encode(v, np.array([[0, -1, 2]], np.int32), 0.0, out)
    with pytest.raises(TypeError, match="float64"):
        export._codec.encode(v.astype(np.float32), np.array([[0, 1, 2]]), 0.0, out)
    with pytest.raises(ValueError, match="50 bytes"):
        export._codec.encode(v, np.array([[0, 1, 2], [0, 1, 2]]), 0.0, out)
