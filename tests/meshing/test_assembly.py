"""Box assembly (``ple.meshing.assembly``): the compiled ``place`` and ``fill`` against their numpy
forms (the same values, bit for bit) and against a direct computation; the template table's
chunks and views; a stream assembled by numpy writes the compiled stream's records."""

import numpy as np
import pytest
from ple.bench.curved import curved_lattice
from ple.io.export import stl_chunk
from ple.meshing import assembly
from ple.meshing.hubs import HubTemplate
from ple.meshing.tessellate import iter_triangles, output_grid

compiled = pytest.mark.skipif(assembly._compiled is None, reason="the compiled assembly is not built")


def _templates(rng, n):
    sizes = rng.integers(1, 40, n), rng.integers(0, 50, n)
    geometry = assembly.TemplateGeometry(1.0, True)
    return [HubTemplate(rng.normal(size=(nv, 3)), rng.integers(0, 30, (nf, 3)), [], [], geometry)
            for nv, nf in zip(*sizes)]


def _similarities(rng, n):
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = q * rng.uniform(0.1, 10, (n, 1, 1))
    m[:, :3, 3] = rng.normal(scale=100, size=(n, 3))
    m[:, 3, 3] = 1
    return m


def _table(rng):
    table = assembly.TemplateTable()
    tpls = _templates(rng, 25)
    with pytest.raises(ValueError, match="not unpacked"):  # its arrays are in no chunk of the table
        table.add(tpls[:1])
    got = table.unpack(assembly.Packed(tpls[:10]))
    table.add(got)
    early = table.snapshot()
    got += table.unpack(assembly.Packed(tpls[10:]))
    table.add(got[10:])  # a second chunk: the earlier snapshot still reads the first
    assert len(early[2]) == 10 and len(early[0]) == 1 and len(table) == 25
    for t, u in zip(tpls, got):  # views of the table, same values
        assert np.array_equal(t.vertices, u.vertices) and np.array_equal(t.faces, u.faces)
        assert u.faces.dtype == np.int32 and any(np.shares_memory(u.vertices, c) for c in table.snapshot()[0])
    return table, got


def test_packed_templates_come_back_equal_and_shared_arrays_once():
    """A template process's ``Packed`` batch, pickled and unpacked into a table: the same
    vertices, faces, rings, caps, r⁺ and clean flags; arrays shared between templates (one
    collapse) are sent once and are one array again; the templates view the table's chunk."""
    import pickle

    rng = np.random.default_rng(4)
    shared_faces = rng.integers(0, 9, (40, 3))
    ring = np.arange(5)
    cap = np.stack([np.full(5, 9), ring[::-1], np.roll(ring[::-1], -1)], axis=1)
    tpls = [HubTemplate(rng.normal(size=(10, 3)), shared_faces if k % 2 else rng.integers(0, 9, (7, 3)),
                        [ring, np.arange(5, 9)], [cap, cap[:3]], assembly.TemplateGeometry(0.1 * k, k != 3))
            for k in range(6)]
    packed = assembly.Packed(tpls)
    assert len(packed.faces) == 40 + 3 * 7  # the shared faces once
    table = assembly.TemplateTable()
    got = table.unpack(pickle.loads(pickle.dumps(packed)))
    table.add(got)
    for a, b in zip(tpls, got):
        assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
        assert all(np.array_equal(x, y) for x, y in zip(a.rings, b.rings))
        assert all(np.array_equal(x, y) for x, y in zip(a.caps, b.caps))
        assert (a.geometry.r_plus, a.geometry.clean) == (b.geometry.r_plus, b.geometry.clean)
        assert np.shares_memory(b.vertices, table.snapshot()[0][0]) and b.faces.dtype == np.int32
    assert got[1].faces is got[3].faces and got[1].rings[0] is got[2].rings[0]
    rows = table.snapshot()[2]
    assert rows[1, 3] == rows[3, 3] and rows[0, 3] != rows[2, 3]


@compiled
def test_place_matches_numpy_and_the_similarities():
    rng = np.random.default_rng(5)
    table, tpls = _table(rng)
    snap = table.snapshot()
    tids = rng.integers(0, len(tpls), 300)
    sizes = np.array([len(tpls[t].vertices) for t in tids])
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]) + 7  # rows 0..6 untouched
    m = _similarities(rng, len(tids))
    out_c = np.full((offsets[-1] + sizes[-1] + 3, 3), np.nan)
    out_n = out_c.copy()
    assembly.place(snap, tids, offsets, m, out_c)
    saved, assembly._compiled = assembly._compiled, None
    try:
        assembly.place(snap, tids, offsets, m, out_n)
    finally:
        assembly._compiled = saved
    assert np.array_equal(out_c, out_n, equal_nan=True)  # bit for bit
    assert np.isnan(out_c[:7]).all() and np.isnan(out_c[-3:]).all()
    for i in range(0, len(tids), 17):
        want = tpls[tids[i]].vertices @ m[i, :3, :3].T + m[i, :3, 3]
        assert np.allclose(out_c[offsets[i]:offsets[i] + sizes[i]], want, rtol=1e-12, atol=1e-9)


@compiled
@pytest.mark.parametrize("index", [np.int32, np.int64])
def test_fill_matches_numpy_and_a_loop(index):
    rng = np.random.default_rng(8)
    pieces = assembly.Pieces()
    want = []
    for _ in range(60):
        local = rng.integers(0, 50, (int(rng.integers(0, 6)), 3))
        a = rng.integers(0, 10**6, int(rng.integers(0, 5)))
        if rng.random() < 0.5:
            pieces.add(local, a)
            want += [local + x for x in a]
        else:
            b = rng.integers(0, 10**6, len(a))
            sides = rng.integers(0, 2, local.shape).astype(np.uint8)
            pieces.add(local, a, b, sides)
            want += [local + np.where(sides == 1, y, x) for x, y in zip(a, b)]
    want = np.concatenate([w.reshape(-1, 3) for w in want])
    packed = pieces.packed()
    local, sides, pf0, pfn, a, b, pa0, pan = packed
    got_c = np.full((len(want) + 4, 3), -1, index)
    got_n = got_c.copy()
    assert assembly.fill(got_c, 2, local, None, sides, pf0, pfn, a, b, pa0, pan) == len(want) + 2
    saved, assembly._compiled = assembly._compiled, None
    try:
        assert assembly.fill(got_n, 2, local, None, sides, pf0, pfn, a, b, pa0, pan) == len(want) + 2
    finally:
        assembly._compiled = saved
    assert np.array_equal(got_c, got_n)
    assert np.array_equal(got_c[2:-2], want) and (got_c[:2] == -1).all() and (got_c[-2:] == -1).all()


@compiled
def test_hub_faces_read_every_chunk():
    rng = np.random.default_rng(2)
    table, tpls = _table(rng)
    tids = rng.integers(0, len(tpls), 50)
    offsets = rng.integers(0, 1000, 50)
    n = sum(len(tpls[t].faces) for t in tids)
    want = np.concatenate([tpls[t].faces + o for t, o in zip(tids, offsets)]).reshape(-1, 3)
    out = np.empty((n, 3), np.int32)
    assert assembly.hub_faces(out, table.snapshot(), tids, offsets) == n
    assert np.array_equal(out, want)
    saved, assembly._compiled = assembly._compiled, None  # numpy: per template, the same faces
    try:
        out[:] = -1
        assert assembly.hub_faces(out, table.snapshot(), tids, offsets) == n
    finally:
        assembly._compiled = saved
    assert np.array_equal(out, want)


@compiled
def test_ranges_are_checked_before_writing():
    rng = np.random.default_rng(3)
    table, tpls = _table(rng)
    snap = table.snapshot()
    out = np.zeros((100, 3))
    with pytest.raises(IndexError, match="template 99"):
        assembly.place(snap, np.array([0, 99]), np.array([0, 0]), _similarities(rng, 2), out)
    with pytest.raises(IndexError):  # past the end of out
        assembly.place(snap, np.array([0]), np.array([100 - len(tpls[0].vertices) + 1]), _similarities(rng, 1), out)
    assert (out == 0).all()
    faces = np.zeros((3, 3), np.int32)
    with pytest.raises(IndexError, match="out of range"):  # 2 × 2 faces do not fit in 3
        assembly.fill(faces, 0, np.zeros((2, 3), np.int32), None, None, [0], [2], [1, 2], None, [0], [2])
    with pytest.raises(IndexError):  # offsets beyond A
        assembly.fill(faces, 0, np.zeros((1, 3), np.int32), None, None, [0], [1], [1], None, [0], [2])
    assert (faces == 0).all()
    with pytest.raises(TypeError):
        assembly.fill(np.zeros((3, 3)), 0, np.zeros((1, 3), np.int32), None, None, [0], [1], [1], None, [0], [1])


def test_numpy_assembly_streams_the_same_records(monkeypatch):
    """Without the compiled assembly (no C compiler), a stream's records are the same bytes."""
    lat = curved_lattice(6)
    grid = output_grid(lat)

    def records():
        return b"".join(stl_chunk(c, grid).tobytes() for c in iter_triangles(lat, None, "refined", 1, max_groups=20))

    first = records()
    monkeypatch.setattr(assembly, "_compiled", None)
    assert records() == first and len(first) > 50 * 1000
