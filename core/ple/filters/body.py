"""Bodies: lattices that fill a part (a closed triangle mesh), by one of three fill modes.

A :class:`Body` is a closed, consistently oriented triangle mesh placed by a similarity. Its
inside test counts signed crossings of a vertical ray (the winding number of a closed surface)
over the triangles of one column of an xy grid; edges are tested with the vertex order fixed by
their indices and ties broken by a symbolic perturbation of the point, so a ray through a shared
edge or vertex is counted exactly once. Distances to the surface are exact point–triangle
distances over the triangles registered in the cells of a 3-D grid that a ball's box meets. Both
are vectorized over points (no Python loop per node) and chunked (memory bounded).

An open mesh (a hole, or faces oriented inconsistently) is refused naming the bad edges, unless
``open="winding"``: then the inside test is the generalized winding number (the sum of the
triangles' solid angles over 4π, ≥ 1/2 inside), brute force over points × triangles.

:class:`BodyFilter` keeps nodes by a fill mode:

- ``inside``: the ball lies wholly inside (centre inside, distance to the surface ≥ radius);
- ``centroid``: the node's group has its template centroid (mean template centre, mapped by the
  group's similarity) inside: whole groups are kept or dropped;
- ``any``: the ball touches the body (centre inside, or distance to the surface < radius).
"""

from __future__ import annotations

import math

import numpy as np

from ..algebra.similarity import Similarity
from ..errors import PleError, echo
from ..model.grading import RadiusField
from ..model.lattice import Lattice
from .base import And, Filter

MODES = ("inside", "centroid", "any")
OPEN_MODES = ("error", "winding")
MAX_ENTRIES = 1 << 23  # (cell, triangle) registrations of one grid before the cells are made coarser
PAIR_CHUNK = 1 << 19  # candidate (point, triangle) pairs per vectorized batch
VOXELS = 128  # cells a side of the grid of inside/outside voxels
MAX_WINDING_WORK = 4 * 10**9  # points × triangles of the open-mesh fallback
WINDING_CHUNK = 1 << 22  # point-triangle terms per batch of the fallback


class Body:
    """A closed triangle mesh: ``vertices`` (V, 3), ``faces`` (F, 3) indices, placed by ``placement``.

    ``source`` is the file it came from (written into ``ple-lattice/1``; None for arrays). A
    closed mesh whose faces point inward is flipped (its signed volume must be positive)."""

    def __init__(self, vertices, faces, placement: Similarity | None = None, source: str | None = None,
                 open: str = "error", name: str = "body") -> None:  # noqa: A002 - the documented option name
        if open not in OPEN_MODES:
            raise PleError(f"{name}: open must be one of {', '.join(OPEN_MODES)}, got {echo(open)}")
        if placement is not None and not isinstance(placement, Similarity):
            raise PleError(f"{name}: placement must be a Similarity")
        v = np.asarray(vertices, dtype=float)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3:
            raise PleError(f"{name}: vertices must be an (V, 3) array, got shape {v.shape}")
        if f.size == 0 or len(v) == 0:
            raise PleError(f"{name}: the mesh is empty (no triangles)")
        if f.ndim != 2 or f.shape[1] != 3 or not np.issubdtype(f.dtype, np.integer):
            raise PleError(f"{name}: faces must be an (F, 3) integer array, got shape {f.shape}")
        bad = int(np.count_nonzero(~np.isfinite(v).all(axis=1)))
        if bad:
            raise PleError(f"{name}: {bad} of {len(v)} vertices are NaN or infinite")
        if f.min() < 0 or f.max() >= len(v):
            raise PleError(f"{name}: face indices must lie in 0..{len(v) - 1}")
        f = f.astype(np.int64)
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])]  # collapsed faces bound nothing
        if len(f) == 0:
            raise PleError(f"{name}: the mesh is empty (every triangle is collapsed)")
        self.name, self.source, self.open = name, source, open
        self.placement = placement or Similarity()
        self.local_vertices = v
        self.vertices = self.placement.apply_points(v)
        unpaired = _unpaired_edges(f, len(v))
        self.closed = unpaired == 0
        if not self.closed and open == "error":
            raise PleError(f"{name}: the mesh is not closed: {unpaired} edges border a hole or join faces of "
                           "opposite orientation (close it, or allow open meshes with open=winding, "
                           "a winding-number fallback)")
        tri = self.vertices[f]
        vol = float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)
        if self.closed and abs(vol) <= 1e-12 * float(np.ptp(self.vertices, axis=0).max()) ** 3:
            raise PleError(f"{name}: the mesh encloses no volume")
        if vol < 0:
            f = f[:, ::-1].copy()
        self.faces = f
        self.volume = abs(vol)
        self.lo, self.hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self._columns = None
        self._edges = None
        self._voxel = None
        self._boxes = None
        self._cells: dict[float, _Grid] = {}

    def __repr__(self) -> str:
        return f"Body({self.source or 'arrays'}, {len(self.faces)} triangles)"

    @property
    def triangles(self) -> np.ndarray:
        """(F, 3, 3) world triangles, outward oriented."""
        return self.vertices[self.faces]

    # ----- inside -------------------------------------------------------------------------------------
    def contains(self, points) -> np.ndarray:
        """bool (N,): which points lie inside the body. Points in a voxel that no triangle's box
        meets take the voxel's label (its centre's exact test); the others are tested exactly."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        if not self.closed:
            return self._winding(p) >= 0.5
        out = np.zeros(len(p), dtype=bool)
        cand = np.flatnonzero(np.all((p >= self.lo) & (p <= self.hi), axis=1))
        if cand.size == 0:
            return out
        grid, label = self._voxels()
        key = grid.keys_of(p[cand])
        lab = label[key]  # 1 inside, 0 outside, -1 a voxel the surface may cross
        out[cand] = lab == 1
        exact = cand[lab < 0]
        out[exact] = self._ray_test(p[exact])
        return out

    def _ray_test(self, p: np.ndarray) -> np.ndarray:
        """Exact inside test: the winding number of the closed surface, from signed crossings of
        the ray from each point towards +z with the faces registered in its column."""
        grid = self._column_grid()
        start, count = grid.lookup(grid.keys_of(p[:, :2]))
        wind = np.zeros(len(p))
        for rows, tris in _pairs(start, count, grid.tri):
            wind += np.bincount(rows, self._crossings(p[rows], tris), minlength=len(p))
        return wind > 0.5

    def _voxels(self):
        """A coarse grid (at most VOXELS cells a side) and per cell: 1 inside, 0 outside, -1 where
        a face's box meets the cell."""
        if self._voxel is None:
            span = float(np.ptp(self.vertices, axis=0).max())
            tri = self.triangles
            grid = _Grid.fit(tri.min(axis=1), tri.max(axis=1), self.lo, self.hi, max(span / VOXELS, 1e-12))
            from scipy import ndimage

            free = np.ones(int(np.prod(grid.dims)), dtype=bool)
            free[grid.keys] = False
            # face-adjacent free voxels share a face no triangle meets: one label per component,
            # taken from the exact test of one voxel centre of each
            comp, count = ndimage.label(free.reshape(tuple(grid.dims)))
            comp = comp.reshape(-1)
            _, first = np.unique(comp, return_index=True)
            first = first[comp[first] > 0]
            ijk = np.stack(np.unravel_index(first, tuple(grid.dims)), axis=1)
            inside = np.zeros(count + 1, dtype=np.int8)
            inside[comp[first]] = self._ray_test(grid.origin + (ijk + 0.5) * grid.h)
            label = np.where(free, inside[comp], -1).astype(np.int8)
            self._voxel = (grid, label)
        return self._voxel

    def _column_grid(self) -> _Grid:
        if self._columns is None:
            lo, hi = self.lo[:2], self.hi[:2]
            area = max(float(np.prod(np.maximum(hi - lo, 1e-300))), 1e-300)
            h = max(math.sqrt(area / len(self.faces)) * 0.7, float(np.ptp(self.vertices[:, :2])) / 4096 + 1e-300)
            tri = self.triangles[:, :, :2]
            self._columns = _Grid.fit(tri.min(axis=1), tri.max(axis=1), lo, hi, h)
        return self._columns

    def _edge_table(self) -> np.ndarray:
        """(F, 3, 7) per face and edge n (the edge opposite vertex n): the edge's first vertex
        (x, y) and direction (dx, dy) in the order of the vertex indices (so both faces of an
        edge compute identical values), the orientation flip, the tie sign (a symbolic
        perturbation p + (ε, ε²) of the point: the sign of -dy, or of dx on a horizontal edge) and
        z of vertex n."""
        if self._edges is None:
            f, v = self.faces, self.vertices
            t = np.empty((len(f), 3, 7))
            for n, (x, y) in enumerate(((1, 2), (2, 0), (0, 1))):
                i, j = f[:, x], f[:, y]
                a, b = np.minimum(i, j), np.maximum(i, j)
                d = v[b, :2] - v[a, :2]
                flip = np.where(i < j, 1.0, -1.0)
                t[:, n, 0:2], t[:, n, 2:4], t[:, n, 4] = v[a, :2], d, flip
                t[:, n, 5] = np.where(d[:, 1] != 0, -np.sign(d[:, 1]), np.sign(d[:, 0])) * flip
                t[:, n, 6] = v[f[:, n], 2]
            self._edges = t
        return self._edges

    def _crossings(self, p: np.ndarray, tris: np.ndarray) -> np.ndarray:
        """+1 / -1 / 0 per (point, triangle) pair: the ray from p towards +z leaves / enters
        through the triangle, or misses it."""
        e = self._edge_table()[tris]  # (M, 3, 7)
        px, py = p[:, 0, None], p[:, 1, None]
        val = e[..., 4] * (e[..., 2] * (py - e[..., 1]) - e[..., 3] * (px - e[..., 0]))  # (M, 3)
        sign = np.where(val != 0, np.sign(val), e[..., 5])
        s = sign.sum(axis=1)
        hit = np.abs(s) == 3  # all three on one side: inside the projected triangle
        # above: the face's plane at (px, py) lies above pz; with barycentric weights w_n = val_n
        # (their sum has the crossing's sign), z_face - pz = Σ w_n (z_n - pz) / Σ w_n
        dz = np.einsum("mn,mn->m", val, e[..., 6] - p[:, 2, None])
        return np.where(hit & (dz * s > 0), np.sign(s), 0.0)

    def _winding(self, p: np.ndarray) -> np.ndarray:
        """Generalized winding numbers (N,) of points (Van Oosterom–Strackee solid angles / 4π)."""
        work = len(p) * len(self.faces)
        if work > MAX_WINDING_WORK:
            raise PleError(f"{self.name}: the winding-number fallback for an open mesh would take {work:.2g} "
                           f"point-triangle terms (limit {MAX_WINDING_WORK:.0e}); close the mesh")
        tri = self.triangles
        out = np.zeros(len(p))
        step = max(1, WINDING_CHUNK // len(tri))
        for s in range(0, len(p), step):
            q = p[s:s + step, None, None, :]
            a, b, c = (tri[None, :, n, :] - q[:, :, 0] for n in range(3))
            la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
            det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
            den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc + np.einsum("pfi,pfi->pf", b, c) * la
                   + np.einsum("pfi,pfi->pf", c, a) * lb)
            out[s:s + step] = 2 * np.arctan2(det, den).sum(axis=1) / (4 * math.pi)
        return out

    # ----- distance to the surface ---------------------------------------------------------------------
    def near(self, points, radii) -> np.ndarray:
        """bool (N,): which balls come closer than their radius to the surface."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        r = np.broadcast_to(np.asarray(radii, dtype=float), (len(p),))
        out = np.zeros(len(p), dtype=bool)
        if self.closed and len(p):  # a ball whose box meets only voxels that no face's box meets is far
            grid, label = self._voxels()
            lo = np.floor((p - r[:, None] - grid.origin) / grid.h).astype(np.int64)
            hi = np.floor((p + r[:, None] - grid.origin) / grid.h).astype(np.int64)
            free = np.all(hi - lo <= 1, axis=1)
            for d in np.ndindex(2, 2, 2):
                cell = np.where(np.array(d, dtype=bool), hi, lo)
                inside = np.all((cell >= 0) & (cell < grid.dims), axis=1)  # beyond the grid: no faces
                rows = np.flatnonzero(free & inside)
                free[rows] = label[grid.linear(cell[rows])] >= 0
            test = np.flatnonzero(~free)
            out[test] = self._near(p[test], r[test])
            return out
        return self._near(p, r)

    def _near(self, p: np.ndarray, r: np.ndarray) -> np.ndarray:
        out = np.zeros(len(p), dtype=bool)
        for rows, tris in self._surface_pairs(p, r):
            rows, tris = self._box_prune(p, r, rows, tris)
            hit = _point_triangle_dist2(p[rows], self.triangles[tris]) < r[rows] ** 2
            out[rows[hit]] = True
        return out

    def distance(self, points, cap: float) -> np.ndarray:
        """Unsigned distance (N,) from points to the surface, clamped to ``cap`` (exact below it)."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        if not cap > 0:
            raise PleError(f"{self.name}: distance cap must be positive, got {echo(cap)}")
        out = np.full(len(p), float(cap) ** 2)
        reach = np.full(len(p), float(cap))
        for rows, tris in self._surface_pairs(p, reach):
            rows, tris = self._box_prune(p, reach, rows, tris)
            np.minimum.at(out, rows, _point_triangle_dist2(p[rows], self.triangles[tris]))
        return np.sqrt(out)

    def signed_distance(self, points, cap: float) -> np.ndarray:
        """Distance to the surface, positive inside and negative outside, clamped to ±cap."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return np.where(self.contains(p), 1.0, -1.0) * self.distance(p, cap)

    def _box_prune(self, p, reach, rows, tris):
        """The pairs whose face box comes within reach of the point (a cheap exact superset)."""
        if self._boxes is None:
            tri = self.triangles
            self._boxes = np.concatenate([tri.min(axis=1), tri.max(axis=1)], axis=1)
        box = self._boxes[tris]
        q = p[rows]
        gap = np.maximum(np.maximum(box[:, :3] - q, q - box[:, 3:]), 0.0)
        ok = np.einsum("ij,ij->i", gap, gap) < reach[rows] ** 2
        return rows[ok], tris[ok]

    def _surface_pairs(self, p: np.ndarray, reach: np.ndarray):
        """Candidate (point row, triangle) pairs: triangles registered in the cells that the box of
        the ball (p, reach) meets; a superset of the triangles within reach."""
        live = np.flatnonzero(np.all((p + reach[:, None] >= self.lo) & (p - reach[:, None] <= self.hi), axis=1))
        if live.size == 0:
            return
        grid = self._cell_grid(float(reach[live].max()))
        cells_lo = np.floor((p[live] - reach[live, None] - grid.origin) / grid.h).astype(np.int64)
        cells_hi = np.floor((p[live] + reach[live, None] - grid.origin) / grid.h).astype(np.int64)
        starts, counts, owners = [], [], []
        for d in np.ndindex(2, 2, 2):  # the cell size is at least twice the reach: at most 2 cells per axis
            cell = cells_lo + d
            ok = np.all((cell <= cells_hi) & (cell >= 0) & (cell < grid.dims), axis=1)
            s, c = grid.lookup(grid.linear(cell[ok]))
            starts.append(s)
            counts.append(c)
            owners.append(live[ok])
        yield from _pairs(np.concatenate(starts), np.concatenate(counts), grid.tri, np.concatenate(owners))

    def _cell_grid(self, reach: float) -> _Grid:
        """A 3-D grid with cells at least 2·reach wide (cached per power-of-two size)."""
        tri = self.triangles
        span = float(np.ptp(self.vertices, axis=0).max())
        # cells about a triangle wide, but no coarser than span/128 (big faces register in many cells)
        base = max(min(float(np.median(np.ptp(tri, axis=1).max(axis=1))), span / 128), span / 1024, 1e-12)
        h = base * 2.0 ** max(0, math.ceil(math.log2(max(2 * reach / base, 1.0))))
        if h not in self._cells:
            self._cells[h] = _Grid.fit(tri.min(axis=1), tri.max(axis=1), self.lo, self.hi, h)
        return self._cells[h]


class _Grid:
    """Triangles registered in the cells of a uniform grid that their boxes meet, sorted by cell."""

    def __init__(self, origin, h, dims, keys, tri) -> None:
        self.origin, self.h, self.dims, self.keys, self.tri = origin, h, dims, keys, tri

    @staticmethod
    def fit(tlo, thi, lo, hi, h) -> _Grid:
        while True:
            dims = np.floor((hi - lo) / h).astype(np.int64) + 1
            a = np.clip(np.floor((tlo - lo) / h).astype(np.int64), 0, dims - 1)
            b = np.clip(np.floor((thi - lo) / h).astype(np.int64), 0, dims - 1)
            ext = b - a + 1
            n = np.prod(ext, axis=1)
            if int(n.sum()) <= MAX_ENTRIES:
                break
            h *= 2.0  # big triangles over fine cells: coarser cells, fewer registrations
        tri = np.repeat(np.arange(len(n)), n)
        pos = np.arange(len(tri)) - np.repeat(np.cumsum(n) - n, n)
        cell = np.empty((len(tri), len(dims)), dtype=np.int64)
        for axis in range(len(dims) - 1, -1, -1):
            e = ext[tri, axis]
            cell[:, axis] = a[tri, axis] + pos % e
            pos //= e
        grid = _Grid(lo, h, dims, None, None)
        keys = grid.linear(cell)
        order = np.argsort(keys, kind="stable")
        grid.keys, grid.tri = keys[order], tri[order]
        return grid

    def linear(self, cell: np.ndarray) -> np.ndarray:
        key = cell[:, 0].copy()
        for axis in range(1, len(self.dims)):
            key = key * self.dims[axis] + cell[:, axis]
        return key

    def keys_of(self, points: np.ndarray) -> np.ndarray:
        cell = np.clip(np.floor((points - self.origin) / self.h).astype(np.int64), 0, self.dims - 1)
        return self.linear(cell)

    def lookup(self, keys: np.ndarray):
        start = np.searchsorted(self.keys, keys, side="left")
        return start, np.searchsorted(self.keys, keys, side="right") - start


def _pairs(start, count, tri, owners=None):
    """(row, triangle) pairs of the runs ``tri[start:start+count]``, in batches of at most
    PAIR_CHUNK pairs; ``row`` is the run's position (or ``owners[position]``)."""
    total = np.cumsum(count)
    first = 0
    while first < len(count):
        last = int(np.searchsorted(total, (total[first - 1] if first else 0) + PAIR_CHUNK, side="right"))
        last = max(last, first + 1)
        c = count[first:last]
        m = int(c.sum())
        if m:
            run = np.repeat(np.arange(first, last), c)
            idx = np.arange(m) - np.repeat(np.cumsum(c) - c, c) + start[run]
            yield (run if owners is None else owners[run]), tri[idx]
        first = last


def _point_triangle_dist2(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Squared distances (N,) from points (N, 3) to triangles (N, 3, 3): to the plane where the
    projection falls inside, else to the nearest of the three edges."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    t = np.einsum("ij,ij->i", p - a, n) / np.where(nn > 0, nn, 1.0)
    q = p - t[:, None] * n
    inside = nn > 0
    for x, y in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(y - x, q - x), n) >= 0
    best = np.where(inside, t * t * nn, np.inf)
    for x, y in ((a, b), (b, c), (c, a)):
        d = y - x
        dd = np.einsum("ij,ij->i", d, d)
        s = np.clip(np.einsum("ij,ij->i", p - x, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        w = p - x - s[:, None] * d
        best = np.minimum(best, np.einsum("ij,ij->i", w, w))
    return best


def _unpaired_edges(faces: np.ndarray, nv: int) -> int:
    """Edges where the directed uses do not cancel (a hole, or faces of opposite orientation)."""
    i = faces.reshape(-1)
    j = faces[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(i, j) * nv + np.maximum(i, j)
    uniq, inv = np.unique(key, return_inverse=True)
    balance = np.bincount(inv, np.where(i < j, 1, -1), minlength=len(uniq))
    return int(np.count_nonzero(balance))


class BodyFilter(Filter):
    """Keeps the nodes that fill ``body`` by ``mode`` (inside, centroid or any)."""

    def __init__(self, body: Body, mode: str = "inside") -> None:
        if not isinstance(body, Body):
            raise PleError(f"a body filter needs a Body, got {type(body).__name__}")
        if mode not in MODES:
            raise PleError(f"fill mode must be one of {', '.join(MODES)}, got {echo(mode)}")
        self.body, self.mode = body, mode

    def node_mask(self, lat: Lattice, node_index, center, radius) -> np.ndarray:
        center = np.asarray(center, dtype=float).reshape(-1, 3)
        radius = np.asarray(radius, dtype=float).reshape(-1)
        if self.mode == "centroid":
            return self._centroids_inside(lat, np.asarray(node_index, dtype=np.int64).reshape(-1, 4))
        keep = self.body.contains(center)
        if self.mode == "inside":
            rows = np.flatnonzero(keep)
            keep[rows] = ~self.body.near(center[rows], radius[rows])
        else:
            rows = np.flatnonzero(~keep)
            keep[rows] = self.body.near(center[rows], radius[rows])
        return keep

    def _centroids_inside(self, lat: Lattice, idx: np.ndarray) -> np.ndarray:
        _, nv, nw = lat.counts
        key = (idx[:, 0] * nv + idx[:, 1]) * nw + idx[:, 2]
        groups, inv = np.unique(key, return_inverse=True)
        gi, rest = np.divmod(groups, nv * nw)
        gj, gk = np.divmod(rest, nw)
        tc = lat.template_centers.mean(axis=0)
        inside = np.empty(len(groups), dtype=bool)
        step = 1 << 16
        for s in range(0, len(groups), step):
            m = lat.group_matrices(gi[s:s + step], gj[s:s + step], gk[s:s + step])
            inside[s:s + step] = self.body.contains(m[:, :3, :3] @ tc + m[:, :3, 3])
        return inside[inv.reshape(-1)]

    def __repr__(self) -> str:
        return f"BodyFilter({self.body!r}, {self.mode!r})"


class SurfaceDistanceField(RadiusField):
    """A radius field graded by the distance d to a body's surface: factor ``f_surface`` on the
    surface, ``f_deep`` from ``depth`` inwards (and outwards), linear in d between."""

    def __init__(self, body: Body, depth: float, f_surface: float = 2.0, f_deep: float = 1.0) -> None:
        if not isinstance(body, Body):
            raise PleError(f"a surface-distance field needs a Body, got {type(body).__name__}")
        if not depth > 0 or not f_surface > 0 or not f_deep > 0:
            raise PleError("a surface-distance field needs a positive depth and positive factors")
        self.body, self.depth, self.f_surface, self.f_deep = body, float(depth), float(f_surface), float(f_deep)
        self.bound = max(self.f_surface, self.f_deep)

    def values(self, points):
        t = self.body.distance(points, self.depth) / self.depth
        return self.f_surface + (self.f_deep - self.f_surface) * t

    def __repr__(self) -> str:
        return f"SurfaceDistanceField({self.body!r}, {self.depth:g}, {self.f_surface:g}, {self.f_deep:g})"



def body_filters(lat: Lattice) -> list[BodyFilter]:
    """The body filters of a lattice, reached through and-compounds in order (a body under or/not
    does not bound what is kept)."""
    out, todo = [], [lat.filter]
    while todo:
        f = todo.pop(0)
        if isinstance(f, And):
            todo[:0] = f.parts
        elif isinstance(f, BodyFilter):
            out.append(f)
    return out


def body_of(lat: Lattice, what: str = "this") -> Body:
    """The body a lattice fills: that of its last body filter (``body_filters``)."""
    found = body_filters(lat)
    if not found:
        raise PleError(f"{what} needs a body: the lattice has no body filter (give --body MESH)")
    return found[-1].body
