"""Box assembly of the streamed tessellation (``ple.meshing.tessellate``): hub templates placed by
each hub's similarity, and faces of repeated local pieces offset into the box's vertex array.

A box holds thousands of hubs, and on curved lattices nearly every one has its own template, so
assembly works on whole boxes, never per template: the templates' vertices and faces live in a
``TemplateTable`` (chunks as the template processes send them, ``Packed``), a box's vertices are
placed hub after hub in one call (``place``), and its faces are written from a list of pieces in
one call (``fill``). Both are compiled (``ple.meshing._assemble``, optional, the GIL released)
with numpy forms computing the same values by the same IEEE operations in the same order
(tested against each other)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from .hubs import HubTemplate

try:  # the compiled assembly (setup.py, optional): the numpy forms' values, without a Python loop per hub
    from . import _assemble as _compiled
except ImportError:  # not built (no C compiler): numpy assembles
    _compiled = None


@dataclass
class TemplateGeometry:
    """What the stream reads of a template's ``HubGeometry``: r⁺, the ACHoCC's clean flag and
    whether a short beam pulled a contact circle in from S⁺ (``achocc.pulled_circles``)."""

    r_plus: float
    clean: bool
    pulled: bool = False


class Packed:
    """Hub templates as a template process sends them back: their vertices (float64) and faces
    (int32) in one array each, rings and caps in one array each, every faces, ring and cap
    array shared between templates (hubs of one collapse) sent once, and of each geometry
    what the stream reads (``TemplateGeometry``). Pickling 4,800 curved-lattice templates one
    by one took 0.6 s, and their arrays were copied once more into the template table."""

    def __init__(self, templates: list):
        self.n = len(templates)
        self.vertices = np.concatenate([np.reshape(t.vertices, (-1, 3)) for t in templates] or [np.zeros((0, 3))])
        self.vertices = self.vertices.astype(float, copy=False)
        self.nv = np.array([len(t.vertices) for t in templates], np.int64)
        self.faces, self.face_lens, self.face_ids = _pack_arrays([[t.faces] for t in templates], 3)
        self.rings, self.ring_lens, self.ring_ids = _pack_arrays([t.rings for t in templates], 1)
        self.caps, self.cap_lens, self.cap_ids = _pack_arrays([t.caps for t in templates], 3)
        self.geometry = [(float(t.geometry.r_plus), bool(t.geometry.clean), bool(t.geometry.pulled)) for t in templates]

    def templates(self, chunk: int) -> list:
        """The templates, their arrays views of this object's, each with its table row (``chunk``:
        the table's chunk of these arrays)."""
        vstart = np.cumsum(self.nv) - self.nv
        faces, fstart = _unpack_arrays(self.faces, self.face_lens)
        rings, _ = _unpack_arrays(self.rings, self.ring_lens)
        caps, _ = _unpack_arrays(self.caps, self.cap_lens)
        out = []
        for k in range(self.n):
            f = self.face_ids[k][0]
            row = (chunk, int(vstart[k]), int(self.nv[k]), int(fstart[f]), int(self.face_lens[f]))
            out.append(HubTemplate(self.vertices[row[1]:row[1] + row[2]], faces[f],
                                   [rings[i] for i in self.ring_ids[k]], [caps[i] for i in self.cap_ids[k]],
                                   TemplateGeometry(*self.geometry[k]), row))
        return out


def _pack_arrays(lists: list, width: int):
    """Per template a list of integer arrays (rows of ``width``) -> (all distinct arrays, by
    identity, concatenated as int32, their row counts, per template the indices of its arrays)."""
    seen: dict = {}
    arrays: list = []
    ids = []
    for lst in lists:
        mine = []
        for a in lst:
            if id(a) not in seen:
                seen[id(a)] = len(arrays)
                arrays.append(a)
            mine.append(seen[id(a)])
        ids.append(mine)
    lens = np.array([len(a) for a in arrays], np.int64)
    flat = np.concatenate([np.asarray(a).reshape(-1, width) for a in arrays]) if arrays else np.zeros((0, width))
    return flat.astype(np.int32).reshape(-1) if width == 1 else flat.astype(np.int32), lens, ids


def _unpack_arrays(flat: np.ndarray, lens: np.ndarray):
    """Views of ``_pack_arrays``' distinct arrays, and their first rows."""
    start = np.cumsum(lens) - lens
    return [flat[a:a + n] for a, n in zip(start.tolist(), lens.tolist())], start


class TemplateTable:
    """The vertices (float64) and faces (int32) of every hub template of a tessellator, in chunks
    never written again: each ``Packed`` batch from a template process is a chunk as it came
    (``unpack``: no copy), and ``add`` registers its templates in template-id order. Readers
    take ``snapshot()`` — the chunks and the rows of each template id so far — and keep reading
    it while later templates are added."""

    def __init__(self):
        self._lock = threading.Lock()
        self._v: list = []
        self._f: list = []
        self._rows: list = []  # per template id: (chunk, vertex start, count, face start, count)
        self._snap = None

    def unpack(self, packed: Packed) -> list:
        """The templates of ``packed``, whose arrays become a chunk of the table."""
        with self._lock:
            chunk = len(self._v)
            self._v.append(packed.vertices)
            self._f.append(packed.faces)
        return packed.templates(chunk)

    def add(self, templates) -> None:
        """Register templates from ``unpack``, in template-id order."""
        templates = list(templates)
        if any(t.row is None for t in templates):
            raise ValueError("a template not unpacked by a template table has no row in one")
        with self._lock:
            self._rows += [t.row for t in templates]
            self._snap = None

    def snapshot(self):
        """(vertex chunks (tuple of (V_c, 3)), face chunks (tuple of int32 (F_c, 3)), rows (T, 5)
        int64: chunk, vertex start, vertex count, face start, face count per template id)."""
        with self._lock:
            if self._snap is None:
                rows = np.array(self._rows, np.int64).reshape(-1, 5)
                self._snap = (tuple(self._v), tuple(self._f), rows)
            return self._snap

    def __len__(self) -> int:
        return len(self._rows)


def place(snapshot, tids: np.ndarray, offsets: np.ndarray, m: np.ndarray, out: np.ndarray) -> None:
    """Vertices of hubs into ``out`` (V, 3): hub i's template tids[i] mapped by m[i] (4×4) into
    rows offsets[i] …, each coordinate ((R₀x + R₁y) + R₂z) + T (the similarity, x' = Rx + T)."""
    tv, _, rows = snapshot
    tids = np.ascontiguousarray(tids, np.int64)
    offsets = np.ascontiguousarray(offsets, np.int64)
    m = np.ascontiguousarray(m, np.float64)
    if _compiled is not None:
        chunk, vstart, vcount = (np.ascontiguousarray(rows[:, k]) for k in range(3))
        _compiled.place(tv, chunk, vstart, vcount, tids, offsets, m, out)
        return
    _place_numpy(tv, rows, tids, offsets, m, out)


def _by_template(tids: np.ndarray):
    """(template id, its hubs in order) for each template of ``tids``, by increasing id."""
    order = np.argsort(tids, kind="stable")
    ut, first = np.unique(tids[order], return_index=True)
    for t, lo, hi in zip(ut, first, np.append(first[1:], len(order))):
        yield t, order[lo:hi]


def _place_numpy(tv, rows, tids, offsets, m, out) -> None:
    """``place`` with numpy: hubs of one template at a time, the compiled form's operations."""
    for t, inst in _by_template(tids):
        c, vs, n = rows[t, :3]
        x, y, z = (tv[c][vs:vs + n, k][None] for k in range(3))
        cols = offsets[inst][:, None] + np.arange(n)[None]
        r = m[inst]
        for j in range(3):
            s = r[:, j, 0, None] * x
            s += r[:, j, 1, None] * y
            s += r[:, j, 2, None] * z
            s += r[:, j, 3, None]
            out[cols, j] = s


def hub_faces(out: np.ndarray, snapshot, tids: np.ndarray, offsets: np.ndarray) -> int:
    """The faces of hubs (their templates' faces, each corner plus the hub's first vertex)
    written into ``out`` from face 0, hub after hub. Returns the faces written."""
    _, tf, rows = snapshot
    n = len(tids)
    if _compiled is None:  # numpy: the hubs of one template at a time (a piece per hub is a Python loop per hub)
        return _hub_faces_numpy(out, tf, rows, np.asarray(tids, np.int64), np.asarray(offsets, np.int64))
    return fill(out, 0, tf, rows[tids, 0], None, rows[tids, 3], rows[tids, 4], offsets,
                None, np.arange(n, dtype=np.int64), np.ones(n, np.int64))


def _hub_faces_numpy(out, tf, rows, tids, offsets) -> int:
    nf = rows[tids, 4]
    pos = np.cumsum(nf) - nf  # each hub's first face, hub after hub
    for t, inst in _by_template(tids):
        c, fs, k = rows[t, 0], rows[t, 3], rows[t, 4]
        f = tf[c][fs:fs + k].astype(out.dtype)
        out[pos[inst][:, None] + np.arange(k)] = f[None] + offsets[inst].astype(out.dtype)[:, None, None]
    return int(nf.sum())


class Pieces:
    """Faces of a box as pieces: local faces (f, 3) repeated for n hubs (or beams), each corner
    plus the hub's offset a (n,) — or, where the piece's corner sides W (f, 3) are 1, the other
    hub's offset b (n,). Collected as lists and packed into arrays for ``fill``."""

    def __init__(self):
        self.local, self.sides, self.a, self.b = [], [], [], []

    def add(self, local: np.ndarray, a: np.ndarray, b: np.ndarray | None = None, sides: np.ndarray | None = None):
        self.local.append(local)
        self.a.append(a)
        self.b.append(a if b is None else b)
        self.sides.append(np.zeros(local.shape, np.uint8) if sides is None else sides)

    def count(self) -> int:
        return sum(len(f) * len(a) for f, a in zip(self.local, self.a))

    def packed(self):
        """(L, W, pf0, pfn, A, B, pa0, pan): ``fill``'s arrays."""
        if not self.local:
            z = np.zeros(0, np.int64)
            return np.zeros((0, 3), np.int32), np.zeros((0, 3), np.uint8), z, z, z, z, z, z
        pfn = np.array([len(f) for f in self.local], np.int64)
        pan = np.array([len(a) for a in self.a], np.int64)
        cat = lambda xs, t: np.concatenate(xs).astype(t, copy=False)  # noqa: E731
        return (cat(self.local, np.int32), cat(self.sides, np.uint8), np.cumsum(pfn) - pfn, pfn,
                cat(self.a, np.int64), cat(self.b, np.int64), np.cumsum(pan) - pan, pan)


def fill(out: np.ndarray, pos: int, local, chunk, sides, pf0, pfn, a, b, pa0, pan) -> int:
    """Write pieces into faces ``out`` (F, 3) from face ``pos`` on: piece p is the pfn[p] local
    faces from row pf0[p] of ``local`` (int32 (l, 3), or a tuple of such chunks, the piece's
    being chunk[p]), once per offset of a[pa0[p]: pa0[p] + pan[p]], each corner plus that offset
    (plus b's where ``sides`` is 1; ``sides`` and ``b`` None: a only). Returns the face after the
    last written."""
    local = tuple(np.ascontiguousarray(x, np.int32) for x in (local if isinstance(local, tuple) else (local,)))
    chunk = None if chunk is None else np.ascontiguousarray(chunk, np.int64)
    sides = None if sides is None else np.ascontiguousarray(sides, np.uint8)
    b = None if b is None else np.ascontiguousarray(b, np.int64)
    pf0, pfn, a, pa0, pan = (np.ascontiguousarray(x, np.int64) for x in (pf0, pfn, a, pa0, pan))
    if _compiled is not None:
        return _compiled.fill(out, int(pos), local, chunk, sides, pf0, pfn, a, b, pa0, pan)
    return _fill_numpy(out, int(pos), local, chunk, sides, pf0, pfn, a, b, pa0, pan)


def _fill_numpy(out, pos, local, chunk, sides, pf0, pfn, a, b, pa0, pan) -> int:
    """``fill`` with numpy, a piece at a time."""
    for p in range(len(pf0)):
        f = local[0 if chunk is None else chunk[p]][pf0[p]:pf0[p] + pfn[p]].astype(out.dtype)
        oa = a[pa0[p]:pa0[p] + pan[p]].astype(out.dtype)
        hi = pos + len(f) * len(oa)
        dst = out[pos:hi].reshape(len(oa), len(f), 3)
        if sides is None or b is None:
            np.add(f[None], oa[:, None, None], out=dst)
        else:
            ob = b[pa0[p]:pa0[p] + pan[p]].astype(out.dtype)
            w = sides[pf0[p]:pf0[p] + pfn[p]].astype(bool)
            np.add(f[None], np.where(w[None], ob[:, None, None], oa[:, None, None]), out=dst)
        pos = hi
    return pos
