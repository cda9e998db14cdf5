"""Voxels and printer slices of any point-membership function (thesis §5.6): a CLG's PMC or a plain
lattice's. Work is estimated before it is done and computed one slab or one layer at a time, so
memory stays proportional to one layer (slices) or to the output array (voxels)."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from ..errors import PleError, echo
from ..model.budget import HUGE, require

MAX_VOXELS = 1 << 32  # 4 GiB of bool output
MAX_PIXELS = 1 << 26  # per printer layer
MAX_LAYERS = 100_000  # printer layers of one slicing (one PNG each)
TILE, MAX_TILE = 16, 64  # voxels per tile side of voxelize_clg (at least; at most)
TILE_ROWS = 1 << 20  # candidate (tile, copy) rows per batch of tiles, about
TILE_WORK_BYTES = TILE_ROWS * 200 + (1 << 18) * 400  # candidate rows with their RangeFinder work; voxel centres
BATCH = 1 << 18  # points per membership call


def parse_bounds(text: str | None, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """``x0,y0,z0,x1,y1,z1`` (or None: the given box)."""
    if text is None:
        return np.asarray(lo, float), np.asarray(hi, float)
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise PleError(f"--bounds {echo(text)}: expected six numbers x0,y0,z0,x1,y1,z1") from None
    if len(vals) != 6 or not np.all(np.isfinite(vals)):
        raise PleError(f"--bounds {echo(text)}: expected six finite numbers x0,y0,z0,x1,y1,z1")
    a, b = np.array(vals[:3]), np.array(vals[3:])
    if np.any(b <= a):
        raise PleError(f"--bounds {echo(text)}: each upper bound must exceed its lower bound")
    if not np.all(np.abs(np.concatenate([a, b])) <= HUGE):  # sizes b - a stay finite
        raise PleError(f"--bounds {echo(text)}: coordinates must lie within ±{HUGE:g}")
    return a, b


def axis_centres(lo: float, hi: float, n: int) -> np.ndarray:
    """Centres lo + (a + ½)(hi − lo)/n, a = 0 … n−1."""
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n


def _membership(pmc: Callable, pts: np.ndarray) -> np.ndarray:
    out = np.empty(len(pts), bool)
    for s in range(0, len(pts), BATCH):
        out[s:s + BATCH] = pmc(pts[s:s + BATCH])
    return out


def check_grid(shape, grids: int = 1, max_bytes: float | None = None) -> tuple[int, int, int]:
    """(NX, NY, NZ) of ``--grid``, refused when ``grids`` bool arrays of it (plus the output) exceed
    ``MAX_VOXELS`` or need more than ``max_bytes`` (``ple.model.budget``)."""
    nx, ny, nz = (int(x) for x in shape)
    if min(nx, ny, nz) < 1:
        raise PleError(f"--grid {nx},{ny},{nz}: every count must be at least 1")
    if nx * ny * nz * grids > MAX_VOXELS:
        held = f"{grids} grids of {nx * ny * nz:.3g} voxels ({nx * ny * nz * grids:.3g})" if grids > 1 else \
            f"{nx * ny * nz:.3g} voxels"
        raise PleError(f"--grid {nx},{ny},{nz}: {held} exceed the limit {MAX_VOXELS:.3g}")
    if max_bytes is not None:
        require(nx * ny * nz * (grids + 1), f"--grid {nx},{ny},{nz}: {nx * ny * nz:.3g} voxels", max_bytes,
                "choose a coarser --grid")
    return nx, ny, nz


def voxelize(pmc: Callable, lo, hi, shape, progress: Callable | None = None, slabs: int | None = None,
             max_bytes: float | None = None) -> np.ndarray:
    """bool (NX, NY, NZ): is each voxel centre inside? computed one x-slab at a time (only the first
    ``slabs`` x-slabs when given: a timing baseline)."""
    nx, ny, nz = check_grid(shape, 1, max_bytes)
    xs, ys, zs = (axis_centres(lo[a], hi[a], n) for a, n in zip(range(3), (nx, ny, nz)))
    xs = xs[:slabs] if slabs is not None else xs
    out = np.empty((len(xs), ny, nz), bool)
    yy, zz = (g.reshape(-1) for g in np.meshgrid(ys, zs, indexing="ij"))
    for a, x in enumerate(xs):
        pts = np.column_stack([np.full(len(yy), x), yy, zz])
        out[a] = _membership(pmc, pts).reshape(ny, nz)
        if progress is not None:
            progress(1)
    return out


def layer_grid(lo, hi, layer: float, pixel: float):
    """(z centres, x centres, y centres) of printer layers of height ``layer`` and square pixels."""
    for name, v in (("--layer", layer), ("--pixel", pixel)):
        if not np.isfinite(v) or v <= 0:
            raise PleError(f"{name} {v}: must be a positive number")
    nf = [max(1.0, float(np.ceil((hi[a] - lo[a]) / step - 1e-9))) for a, step in ((0, pixel), (1, pixel), (2, layer))]
    if not nf[2] <= MAX_LAYERS:  # counted as floats first: a tiny step over a huge box is no integer overflow
        raise PleError(f"--layer {layer}: {nf[2]:.3g} layers exceed the limit {MAX_LAYERS:,}")
    if not nf[0] * nf[1] <= MAX_PIXELS:
        raise PleError(f"--pixel {pixel}: {nf[0]:.3g}x{nf[1]:.3g} pixels per layer exceed the limit {MAX_PIXELS:.3g}")
    n = [int(x) for x in nf]
    if n[0] * n[1] > MAX_PIXELS:
        raise PleError(f"--pixel {pixel}: {n[0]}x{n[1]} pixels per layer exceed the limit {MAX_PIXELS:.3g}")
    xs = lo[0] + (np.arange(n[0]) + 0.5) * pixel
    ys = lo[1] + (np.arange(n[1]) + 0.5) * pixel
    zs = lo[2] + (np.arange(n[2]) + 0.5) * layer
    return zs, xs, ys


def iter_slices(pmc: Callable, lo, hi, layer: float, pixel: float, layers: range | None = None
                ) -> Iterator[tuple[int, float, np.ndarray]]:
    """(index, z, mask (ny, nx) bool, row 0 at the largest y: image order) per layer, one at a time;
    only the layer indices of ``layers`` when given (a part of a partitioned slice job)."""
    zs, xs, ys = layer_grid(lo, hi, layer, pixel)
    gx, gy = np.meshgrid(xs, ys[::-1])
    flat = np.column_stack([gx.reshape(-1), gy.reshape(-1), np.zeros(gx.size)])
    for k in range(len(zs)) if layers is None else layers:
        z = zs[k]
        flat[:, 2] = z
        yield k, float(z), _membership(pmc, flat).reshape(gx.shape)


def voxelize_clg(comp, lo, hi, shape, progress: Callable | None = None, max_bytes: float | None = None) -> np.ndarray:
    """Voxels of a compiled CLG by chunk copies (§5.6), the copies found by the RangeFinder: the grid
    is cut into tiles, each tile's enclosing ball asks which chunk copies it may touch (the box and
    conical-shell bounds, then ``Compiled.candidates``), and each such copy classifies only the
    voxels of the tile inside the boxes of its positive primitives' balls; the chunk
    unions are OR-ed and the solid is combined from them. The same centres and result as PMC per
    voxel; work follows the copies near the grid, not the pattern's size."""
    nx, ny, nz = check_grid(shape, len(comp.names) + 1, max_bytes)
    if max_bytes is not None:  # a batch of candidate copies and of voxel centres, besides the grids
        require(TILE_WORK_BYTES, "one batch of candidate chunk copies and voxel centres", max_bytes)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n = np.array([nx, ny, nz])
    step = (hi - lo) / n
    side = _tile_side(comp, step, n)
    t0 = np.stack(np.meshgrid(*(np.arange(0, n[a], side[a]) for a in range(3)), indexing="ij"), -1).reshape(-1, 3)
    t1 = np.minimum(t0 + side, n)
    first, last = lo + (t0 + 0.5) * step, lo + (t1 - 0.5) * step  # the tiles' outermost voxel centres
    centre, radius = (first + last) / 2, np.linalg.norm(last - first, axis=1) / 2
    unions = [np.zeros((nx, ny, nz), bool) for _ in comp.names]
    pad = 1e-9 * max(comp.scale, float(np.max(np.abs(hi - lo))))
    batch, s = 8, 0
    while s < len(t0):
        tiles = np.arange(s, min(s + batch, len(t0)))
        tiles = tiles[comp.near(centre[tiles], radius[tiles])]
        q, g, c = (comp.candidates(centre[tiles], radius[tiles]) if len(tiles)
                   else (np.zeros(0, np.int64), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)))
        for ci in range(len(comp.names)):
            sel = c == ci
            if sel.any():
                _classify(comp, ci, g[sel], t0[tiles[q[sel]]], t1[tiles[q[sel]]], lo, step, pad, unions[ci])
        if progress is not None:
            progress(min(s + batch, len(t0)) - s)
        s += batch
        batch = max(1, batch * 2 if len(q) < TILE_ROWS // 4 else batch // 2 if len(q) > TILE_ROWS else batch)
    return comp.combine_bool(unions)


def voxel_tiles(comp, lo, hi, shape) -> int:
    """The number of tiles ``voxelize_clg`` cuts the grid into (its progress total)."""
    n = np.asarray(shape, dtype=np.int64)
    side = _tile_side(comp, (np.asarray(hi, float) - np.asarray(lo, float)) / n, n)
    return int(np.prod(-(-n // side)))


def _tile_side(comp, step: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Voxels per tile side (3,): at least ``TILE``, and about two chunk copies across (a copy's
    box measured at the first group of the copies), at most ``MAX_TILE``."""
    r = comp.region if comp.region is not None else comp.lat.region(None)
    g0 = np.array([[r.i0, r.j0, r.k0]])
    size = 0.0
    for ci in range(len(comp.names)):
        for ca, ra, cb, rb in comp.prim_balls(comp.positive[ci], g0):
            ext = [ca - ra[:, None], ca + ra[:, None]] + ([] if cb is None else [cb - rb[:, None], cb + rb[:, None]])
            size = max(size, float(np.max(np.max(ext, axis=0) - np.min(ext, axis=0))))
    side = np.ceil(2 * size / np.where(step > 0, step, 1.0))
    return np.clip(side, TILE, MAX_TILE).astype(np.int64).clip(1, np.maximum(n, 1))


def _classify(comp, ci: int, g: np.ndarray, a0: np.ndarray, a1: np.ndarray, lo, step, pad, grid) -> None:
    """OR into ``grid`` the voxels of chunk ``ci``'s copies at groups ``g`` (m, 3) that lie in the
    voxel boxes [a0, a1) (m, 3) and in the box of one of the copy's positive primitives (whose
    union holds the copy); in batches of ``BATCH`` voxel centres."""
    for ca, ra, cb, rb in comp.prim_balls(comp.positive[ci], g):
        box_lo, box_hi = ca - ra[:, None], ca + ra[:, None]
        if cb is not None:
            box_lo, box_hi = np.minimum(box_lo, cb - rb[:, None]), np.maximum(box_hi, cb + rb[:, None])
        b0 = np.maximum(np.ceil((box_lo - pad - lo) / step - 0.5), a0).astype(np.int64)
        b1 = np.minimum(np.floor((box_hi + pad - lo) / step - 0.5) + 1, a1).astype(np.int64)
        size = np.maximum(b1 - b0, 0)
        count = size.prod(axis=1)
        keep = count > 0
        gg, b0, size, count = g[keep], b0[keep], size[keep], count[keep]
        ends = np.cumsum(count)
        start = 0
        while start < len(gg):  # pairs whose voxels fill one batch (at least one pair)
            stop = max(start + 1, int(np.searchsorted(ends, (ends[start - 1] if start else 0) + BATCH, "right")))
            cnt = count[start:stop]
            row = np.repeat(np.arange(start, stop), cnt)
            local = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            yz = size[row, 1] * size[row, 2]
            idx = np.column_stack([b0[row, 0] + local // yz, b0[row, 1] + (local % yz) // size[row, 2],
                                   b0[row, 2] + local % size[row, 2]])
            fresh = ~grid[idx[:, 0], idx[:, 1], idx[:, 2]]  # a voxel already inside stays inside
            idx, row = idx[fresh], row[fresh]
            val = comp.chunk_value(ci, lo + (idx + 0.5) * step, gg[row], np.zeros(len(row)))[0]
            inside = idx[val <= 0]
            grid[inside[:, 0], inside[:, 1], inside[:, 2]] = True
            start = stop


def voxel_surface(vox, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The boundary of the filled voxels of ``vox`` (NX, NY, NZ) over the box [lo, hi]: vertices
    (m, 3) at voxel corners and quads (f, 4), counter-clockwise seen from outside (one quad per face
    between a filled and an empty voxel, so the enclosed volume is the filled voxels' volume)."""
    v = np.pad(np.asarray(vox, bool), 1)
    n = np.array(v.shape) - 2
    step = (np.asarray(hi, float) - np.asarray(lo, float)) / n
    quads = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3  # e_b × e_c = e_a: (0,0) (1,0) (1,1) (0,1) turns about +a
        below, above = [slice(1, -1)] * 3, [slice(1, -1)] * 3
        below[a], above[a] = slice(0, n[a] + 1), slice(1, n[a] + 2)
        lower, upper = v[tuple(below)], v[tuple(above)]
        for mask, order in ((lower & ~upper, (0, 1, 2, 3)), (~lower & upper, (3, 2, 1, 0))):
            base = np.argwhere(mask)
            ring = [base, base.copy(), base.copy(), base.copy()]
            ring[1][:, b] += 1
            ring[2][:, b] += 1
            ring[2][:, c] += 1
            ring[3][:, c] += 1
            quads.append(np.stack([ring[k] for k in order], axis=1))
    quads = np.concatenate(quads).reshape(-1, 4, 3)
    flat = np.ravel_multi_index(quads.reshape(-1, 3).T, tuple(n + 1))
    used, inverse = np.unique(flat, return_inverse=True)
    corners = np.column_stack(np.unravel_index(used, tuple(n + 1)))
    return np.asarray(lo, float) + corners * step, inverse.reshape(-1, 4)
