"""First-hit ray casting against axis-aligned boxes on flat ground (numba).

Boxes are binned on a uniform 2D grid over their xy extent; a ray walks the bins it
crosses (Amanatides-Woo) and tests each box of a bin with the slab method, stopping
once the nearest hit lies before the bin's exit. The ground plane z = 0 ends every
descending ray. All kernels use ``error_model="numpy"`` so 1/0 is inf, not an error.
"""

from __future__ import annotations

import dataclasses
import math

import numba as nb
import numpy as np
import numpy.typing as npt

from common.arrays import F64, I64

_PAR = 1e-12

# What the kernels take, as one argument each (numba passes tuples by value, at no
# cost): the binned boxes, ``BoxGrid.args``; and the visibility table being filled for
# a chunk of candidates, (dims, offset, base, counts, rng) with ``Field.cell_dims`` and
# ``Field.cell_offset``; ``counts`` and ``rng``, flat, hold the hit counts and nearest
# ranges of the cells of the plots within range of each candidate, those of plot p
# for candidate a from ``base[a, p]`` (-1: p is out of a's range), so the table grows
# with the plots in range, not with the field (:func:`record`).
GridArgs = tuple[F64, float, float, float, float, int, int, I64, I64, float]
Table = tuple[I64, I64, I64, npt.NDArray[np.int32], npt.NDArray[np.float32]]


@dataclasses.dataclass(frozen=True, eq=False)
class BoxGrid:
    """Boxes (P, 6) ``[xmin, ymin, zmin, xmax, ymax, zmax]`` binned on an xy grid:
    bin (i, j) holds ``items[start[i * ny + j] : start[i * ny + j + 1]]``."""

    boxes: F64
    x0: float
    y0: float
    bx: float
    by: float
    nx: int
    ny: int
    start: I64
    items: I64
    zmax: float

    @property
    def args(self) -> GridArgs:
        """The grid as the numba kernels take it."""
        return (
            self.boxes,
            self.x0,
            self.y0,
            self.bx,
            self.by,
            self.nx,
            self.ny,
            self.start,
            self.items,
            self.zmax,
        )


def build_grid(boxes: F64) -> BoxGrid:
    """Bin ``boxes`` on bins the size of a median box, so a bin holds one or two."""
    boxes = np.ascontiguousarray(boxes, dtype=np.float64)
    if boxes.ndim != 2 or boxes.shape[1] != 6 or len(boxes) == 0:
        raise ValueError(f"boxes: expected a non-empty (P, 6) array, got shape {boxes.shape}")
    if np.any(boxes[:, 3:] < boxes[:, :3]):
        raise ValueError("boxes: some box has max < min")
    lo, hi = boxes[:, :2].min(axis=0), boxes[:, 3:5].max(axis=0)
    size = np.maximum(np.median(boxes[:, 3:5] - boxes[:, :2], axis=0), 1e-3)
    n = np.clip(np.ceil((hi - lo) / size), 1, 4096).astype(np.int64)
    b = np.maximum((hi - lo) / n, 1e-9)
    i0 = np.clip(((boxes[:, 0] - lo[0]) / b[0]).astype(np.int64), 0, n[0] - 1)
    i1 = np.clip(((boxes[:, 3] - lo[0]) / b[0]).astype(np.int64), 0, n[0] - 1)
    j0 = np.clip(((boxes[:, 1] - lo[1]) / b[1]).astype(np.int64), 0, n[1] - 1)
    j1 = np.clip(((boxes[:, 4] - lo[1]) / b[1]).astype(np.int64), 0, n[1] - 1)
    pairs: list[tuple[int, int]] = []
    for p in range(len(boxes)):
        for i in range(i0[p], i1[p] + 1):
            for j in range(j0[p], j1[p] + 1):
                pairs.append((int(i * n[1] + j), p))
    arr = np.array(sorted(pairs), dtype=np.int64)
    start = np.searchsorted(arr[:, 0], np.arange(n[0] * n[1] + 1)).astype(np.int64)
    return BoxGrid(
        boxes,
        float(lo[0]),
        float(lo[1]),
        float(b[0]),
        float(b[1]),
        int(n[0]),
        int(n[1]),
        start,
        np.ascontiguousarray(arr[:, 1]),
        float(boxes[:, 5].max()),
    )


def in_range(o: F64, boxes: F64, reach: float) -> npt.NDArray[np.bool_]:
    """(k, P): whether the nearest point of each box ``[xmin, ymin, zmin, xmax, ymax,
    zmax]`` lies within ``reach`` of each origin ``o`` (k, d), d = 2 (plan view) or 3."""
    d = o.shape[1]
    lo, hi = boxes[None, :, :d], boxes[None, :, 3 : 3 + d]
    gap = np.maximum(np.maximum(lo - o[:, None, :], 0.0), o[:, None, :] - hi)
    return (gap * gap).sum(axis=2) <= reach * reach


@nb.njit(inline="always", cache=True, error_model="numpy")
def _slab(lo: float, hi: float, o: float, inv: float, d: float) -> tuple[float, float]:
    # Treat |d| < _PAR as parallel: 1/d would overflow and 0 * inf give NaN; over any
    # range we cast (< 1e4 m) the ray moves less than 1e-8 m along that axis.
    if abs(d) < _PAR:
        if o < lo or o > hi:
            return math.inf, -math.inf
        return -math.inf, math.inf
    t1 = (lo - o) * inv
    t2 = (hi - o) * inv
    return (t1, t2) if t1 < t2 else (t2, t1)


@nb.njit(cache=True, error_model="numpy")
def ray_box(
    b: F64, ox: float, oy: float, oz: float, dx: float, dy: float, dz: float
) -> tuple[float, float]:
    """Slab-method entry and exit parameters of the line o + t d through box ``b``
    (entry > exit means no intersection)."""
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    a0, a1 = _slab(b[0], b[3], ox, ix, dx)
    b0, b1 = _slab(b[1], b[4], oy, iy, dy)
    c0, c1 = _slab(b[2], b[5], oz, iz, dz)
    return max(a0, b0, c0), min(a1, b1, c1)


@nb.njit(cache=True, error_model="numpy")
def first_hit(
    ox: float,
    oy: float,
    oz: float,
    dx: float,
    dy: float,
    dz: float,
    tmax: float,
    grid: GridArgs,
) -> tuple[int, float]:
    """Index of the first box hit by o + t d for t in [0, tmax], and its t; (-1, inf)
    when the ray reaches tmax or the ground first."""
    boxes, x0, y0, bx, by, nx, ny, start, items, zmax = grid
    if dz < 0.0:
        tmax = min(tmax, -oz / dz)
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    a0, a1 = _slab(x0, x0 + nx * bx, ox, ix, dx)
    b0, b1 = _slab(y0, y0 + ny * by, oy, iy, dy)
    c0, c1 = _slab(0.0, zmax, oz, iz, dz)
    t0 = max(a0, b0, c0, 0.0)
    t1 = min(a1, b1, c1, tmax)
    if t0 > t1:
        return -1, math.inf
    px = ox + t0 * dx
    py = oy + t0 * dy
    i = min(max(int((px - x0) / bx), 0), nx - 1)
    j = min(max(int((py - y0) / by), 0), ny - 1)
    si = 1 if dx > 0 else -1
    sj = 1 if dy > 0 else -1
    nxt_x = x0 + (i + (1 if dx > 0 else 0)) * bx
    nxt_y = y0 + (j + (1 if dy > 0 else 0)) * by
    tx = (nxt_x - ox) * ix if abs(dx) >= _PAR else math.inf
    ty = (nxt_y - oy) * iy if abs(dy) >= _PAR else math.inf
    ddx = bx * abs(ix) if abs(dx) >= _PAR else math.inf
    ddy = by * abs(iy) if abs(dy) >= _PAR else math.inf
    best = -1
    best_t = math.inf
    while True:
        cell = i * ny + j
        for k in range(start[cell], start[cell + 1]):
            p = items[k]
            e0, e1 = _slab(boxes[p, 0], boxes[p, 3], ox, ix, dx)
            f0, f1 = _slab(boxes[p, 1], boxes[p, 4], oy, iy, dy)
            g0, g1 = _slab(boxes[p, 2], boxes[p, 5], oz, iz, dz)
            tn = max(e0, f0, g0, 0.0)
            tf = min(e1, f1, g1, t1)
            if tn <= tf and tn < best_t:
                best_t = tn
                best = p
        t_exit = min(tx, ty)
        if best_t <= t_exit or t_exit > t1:
            break
        if tx < ty:
            i += si
            tx += ddx
            if i < 0 or i >= nx:
                break
        else:
            j += sj
            ty += ddy
            if j < 0 or j >= ny:
                break
    return best, best_t


@nb.njit(inline="always", cache=True, error_model="numpy")
def cell_of(p: int, x: float, y: float, z: float, boxes: F64, dims: I64, offset: I64) -> int:
    """Cell of plot ``p`` containing the (boundary) point (x, y, z)."""
    nx, ny, nz = dims[p, 0], dims[p, 1], dims[p, 2]
    i = int((x - boxes[p, 0]) / (boxes[p, 3] - boxes[p, 0]) * nx)
    j = int((y - boxes[p, 1]) / (boxes[p, 4] - boxes[p, 1]) * ny)
    k = int((z - boxes[p, 2]) / (boxes[p, 5] - boxes[p, 2]) * nz)
    i = min(max(i, 0), nx - 1)
    j = min(max(j, 0), ny - 1)
    k = min(max(k, 0), nz - 1)
    return offset[p] + (i * ny + j) * nz + k


@nb.njit(cache=True, error_model="numpy")
def record(a: int, p: int, cell: int, dist: float, out: Table) -> None:
    """Candidate ``a`` sees ``cell`` (of plot ``p``) once more, at ``dist`` metres."""
    _, offset, base, counts, rng = out
    k = base[a, p] + cell - offset[p]
    counts[k] += 1
    if dist < rng[k]:
        rng[k] = dist


@nb.njit(parallel=True, cache=True, error_model="numpy")
def _cast_many(
    origins: F64,
    dirs: F64,
    tmax: F64,
    grid: GridArgs,
) -> tuple[I64, F64]:
    n = origins.shape[0]
    hit = np.empty(n, dtype=np.int64)
    ts = np.empty(n, dtype=np.float64)
    for r in nb.prange(n):
        o = origins[r]
        d = dirs[r]
        h, t = first_hit(
            o[0],
            o[1],
            o[2],
            d[0],
            d[1],
            d[2],
            tmax[r],
            grid,
        )
        hit[r] = h
        ts[r] = t
    return hit, ts


def cast(grid: BoxGrid, origins: F64, dirs: F64, tmax: float | F64 = math.inf) -> tuple[I64, F64]:
    """First box hit by each ray ``origins[r] + t * dirs[r]``, 0 <= t <= tmax (t in
    units of ``|dirs[r]|``): box index (-1 for none, ground included) and t."""
    o = np.ascontiguousarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(dirs, dtype=np.float64).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and dirs {d.shape} differ in shape")
    tm = np.broadcast_to(np.asarray(tmax, dtype=np.float64), (len(o),)).copy()
    return _cast_many(o, d, tm, grid.args)
