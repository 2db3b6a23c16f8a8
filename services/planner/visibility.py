"""Visibility of plot cells from candidate scan locations.

Two modes, one ray caster (:mod:`services.planner.raycast`), first hit only so plots
occlude each other and the ground ends descending rays:

- ``grid``: the paper's method, rays on the scanner's angular grid (0.36 deg gives
  1000 x 417 rays per location); a cell is seen by the rays whose first hit lies in it.
- ``exact`` (default): resolution-free up to the sampling of each exposed cell face by
  ``samples x samples`` points; a cell is visible when a straight line from the optical
  centre to one of those points meets nothing before it, within the range limits and the
  vertical field of view. The grid result converges to it as the step shrinks.

The result is a sparse (COO) table: candidate index, cell, hit count (rays or sample
points), nearest range.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable

import numba as nb
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from common.field import Field, ScannerModel
from services.planner.exact import exact_kernel
from services.planner.faces import exposed_faces
from services.planner.raycast import GridArgs, Table, build_grid, cell_of, first_hit

log = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
Progress = Callable[[int, int], None]


@dataclasses.dataclass(frozen=True, eq=False)
class Visibility:
    """Sparse visibility table. ``cand`` indexes ``Field.cand_xy`` (not the ids)."""

    cand: I64
    cell: I64
    hits: I64
    range_min: F64  # metres from the optical centre to the nearest seen point
    n_candidates: int
    n_cells: int
    rays: int
    mode: str

    def matrix(self, min_hits: int = 1) -> sp.csr_matrix:
        """(candidates x cells) boolean CSR of pairs seen by at least ``min_hits``."""
        keep = self.hits >= min_hits
        data = np.ones(int(keep.sum()), dtype=bool)
        shape = (self.n_candidates, self.n_cells)
        return sp.csr_matrix((data, (self.cand[keep], self.cell[keep])), shape=shape)

    def cell_min_range(self) -> F64:
        """Nearest range at which each cell is seen (inf where never)."""
        out = np.full(self.n_cells, np.inf)
        np.minimum.at(out, self.cell, self.range_min)
        return out

    def cell_views(self, min_hits: int = 1) -> I64:
        """Number of candidates that see each cell."""
        keep = self.hits >= min_hits
        return np.bincount(self.cell[keep], minlength=self.n_cells).astype(np.int64)


def grid_directions(scanner: ScannerModel, step_deg: float | None = None) -> F64:
    """Unit ray directions (M, 3) of the scanner's angular grid, field frame."""
    step = scanner.step_deg if step_deg is None else step_deg
    v = np.arange(scanner.vertical_start_deg, scanner.vertical_end_deg + 1e-9, step)
    span = scanner.horizontal_end_deg - scanner.horizontal_start_deg
    nh = round(span / step) if span >= 360 - 1e-9 else int(span / step + 1e-9) + 1
    h = scanner.horizontal_start_deg + step * np.arange(nh)
    vv, hh = np.meshgrid(np.radians(v), np.radians(h), indexing="ij")
    d = np.stack([np.cos(vv) * np.cos(hh), np.cos(vv) * np.sin(hh), np.sin(vv)], axis=-1)
    return np.ascontiguousarray(d.reshape(-1, 3))


@nb.njit(parallel=True, cache=True, error_model="numpy")
def _grid_kernel(
    origins: F64,
    dirs: F64,
    rmin: float,
    rmax: float,
    grid: GridArgs,
    out: Table,
) -> None:
    boxes = grid[0]
    dims, offset, counts, rng = out
    for a in nb.prange(origins.shape[0]):
        counts[a, :] = 0
        rng[a, :] = np.inf
        ox, oy, oz = origins[a, 0], origins[a, 1], origins[a, 2]
        for r in range(dirs.shape[0]):
            dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
            p, t = first_hit(ox, oy, oz, dx, dy, dz, rmax, grid)
            if p >= 0 and t >= rmin:
                c = cell_of(p, ox + t * dx, oy + t * dy, oz + t * dz, boxes, dims, offset)
                counts[a, c] += 1
                if t < rng[a, c]:
                    rng[a, c] = t


def _chunks(n: int, n_cells: int) -> list[tuple[int, int]]:
    # Small chunks into one reused dense buffer (int32 + float32 per cell, <= 64 MB):
    # fresh large buffers per chunk cost more in page faults than the casting itself.
    size = max(1, min(n, 32, (64 << 20) // max(1, 8 * n_cells)))
    return [(s, min(n, s + size)) for s in range(0, n, size)]


def compute_visibility(
    field: Field,
    scanner: ScannerModel,
    mode: str = "exact",
    *,
    samples: int = 3,
    cull_sides: bool = True,
    step_deg: float | None = None,
    progress: Progress | None = None,
) -> Visibility:
    """Visibility table of every candidate of ``field``.

    ``mode`` is ``"exact"`` (``samples`` x ``samples`` points per exposed cell face) or
    ``"grid"`` (``step_deg``, default the scanner's step). ``cull_sides`` skips plot
    sides that one box provably hides (same result, faster; off only to check that).
    ``progress(done, total)`` is called after each chunk of candidates. Raises
    ValueError on a bad mode or sampling.
    """
    if mode not in ("exact", "grid"):
        raise ValueError(f"visibility mode {mode!r}: expected 'exact' or 'grid'")
    if samples < 1:
        raise ValueError(f"samples={samples}: expected >= 1")
    g = build_grid(field.plot_boxes)
    n, nc = field.n_candidates, field.n_cells
    origins = np.column_stack([field.cand_xy, np.full(n, scanner.height)])
    if mode == "grid":
        dirs = grid_directions(scanner, step_deg)
    else:
        faces, fint, side_start = exposed_faces(field)
        # planar occlusion (see services.planner.exact) holds when every plot stands on the ground
        # and reaches the optical centre
        cull = bool(np.all(g.boxes[:, 2] <= 0.0) and np.all(g.boxes[:, 5] >= scanner.height))
        cull = cull and cull_sides
    hspan = scanner.horizontal_end_deg - scanner.horizontal_start_deg
    out_c: list[I64] = []
    out_k: list[I64] = []
    out_h: list[I64] = []
    out_r: list[F64] = []
    rays = 0
    t0 = last_log = time.perf_counter()
    chunks = _chunks(n, nc)
    size = chunks[0][1] - chunks[0][0] if chunks else 0
    buf_c = np.zeros((size, nc), dtype=np.int32)
    buf_r = np.zeros((size, nc), dtype=np.float32)
    for s, e in chunks:
        o = np.ascontiguousarray(origins[s:e])
        counts, rng = buf_c[: e - s], buf_r[: e - s]
        table = (field.cell_dims, field.cell_offset, counts, rng)
        if mode == "grid":
            _grid_kernel(o, dirs, scanner.min_range, scanner.max_range, g.args, table)
            rays += len(o) * len(dirs)
        else:
            limits = (
                scanner.min_range,
                scanner.max_range,
                scanner.vertical_start_deg,
                scanner.vertical_end_deg,
                scanner.horizontal_start_deg,
                hspan,
            )
            nr = exact_kernel(o, limits, samples, cull, faces, fint, side_start, g.args, table)
            rays += int(nr.sum())
        ci, ki = np.nonzero(counts)
        out_c.append(ci.astype(np.int64) + s)
        out_k.append(ki.astype(np.int64))
        out_h.append(counts[ci, ki].astype(np.int64))
        out_r.append(rng[ci, ki].astype(np.float64))
        now = time.perf_counter()
        if now - last_log > 2.0 or e == n:
            log.info("visibility (%s): %d/%d candidates, %.1f s", mode, e, n, now - t0)
            last_log = now
        if progress is not None:
            progress(e, n)
    return Visibility(
        cand=np.concatenate(out_c),
        cell=np.concatenate(out_k),
        hits=np.concatenate(out_h),
        range_min=np.concatenate(out_r),
        n_candidates=n,
        n_cells=nc,
        rays=rays,
        mode=mode,
    )
