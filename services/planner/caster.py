"""Casting the rays of chosen candidates (:class:`Caster`), for
:func:`.visibility.compute_visibility`: the paper's angular grid or the exact
(face-sampling) kernels of :mod:`.exact`, into flat tables that hold, for each
candidate, only the cells of the plots within the scanner's range (:class:`_Scratch`,
:func:`.raycast.in_range`)."""

from __future__ import annotations

import numba as nb
import numpy as np

from common.arrays import F32, F64, I32, I64
from common.field import Field, ScannerModel
from services.planner.exact import exact_kernel
from services.planner.faces import exposed_faces
from services.planner.raycast import (
    GridArgs,
    Table,
    build_grid,
    cell_of,
    first_hit,
    in_range,
    record,
)

Pairs = tuple[I32, I32, I32, F32]  # candidate, cell, hits, nearest range
Cast = tuple[Pairs, int]  # a chunk's pairs and the rays cast for them


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
    dims, offset, base = out[0], out[1], out[2]
    for a in nb.prange(origins.shape[0]):
        ox, oy, oz = origins[a, 0], origins[a, 1], origins[a, 2]
        for r in range(dirs.shape[0]):
            dx, dy, dz = dirs[r, 0], dirs[r, 1], dirs[r, 2]
            p, t = first_hit(ox, oy, oz, dx, dy, dz, rmax, grid)
            # a hit within rmax lies in a plot within rmax: base[a, p] >= 0
            if p >= 0 and t >= rmin and base[a, p] >= 0:
                c = cell_of(p, ox + t * dx, oy + t * dy, oz + t * dz, boxes, dims, offset)
                record(a, p, c, t, out)


CHUNK = 32  # candidates per kernel call: both cores busy, progress every few seconds


class _Scratch:
    """The flat tables of a chunk of candidates (:data:`raycast.Table`): the cells of
    the plots within range of each, laid out one candidate after the other, in
    buffers reused from chunk to chunk (fresh large ones cost more in page faults than
    the casting) and grown when a chunk needs more."""

    def __init__(self, field: Field, rmax: float) -> None:
        self.boxes = field.plot_boxes
        self.offset = field.cell_offset
        self.ncells = np.diff(field.cell_offset)
        self.rmax = rmax
        self.counts = np.zeros(0, dtype=np.int32)
        self.rng = np.zeros(0, dtype=np.float32)

    def table(self, o: F64, dims: I64) -> tuple[Table, I64, I64]:
        """The zeroed table of the origins ``o`` (k, 3); with, for each slot of the
        flat buffers' plots, the plot and the candidate row it belongs to."""
        near = in_range(o, self.boxes, self.rmax)
        rows, plots = np.nonzero(near)
        sizes = self.ncells[plots]
        starts = np.concatenate([[0], np.cumsum(sizes)])
        base = np.full(near.shape, -1, dtype=np.int64)
        base[rows, plots] = starts[:-1]
        total = int(starts[-1])
        if total > len(self.counts):
            self.counts = np.zeros(total, dtype=np.int32)
            self.rng = np.zeros(total, dtype=np.float32)
        counts, rng = self.counts[:total], self.rng[:total]
        counts[:] = 0
        rng[:] = np.inf
        return (dims, self.offset, base, counts, rng), starts, np.column_stack([rows, plots])

    def pairs(self, table: Table, starts: I64, owner: I64) -> tuple[I64, I64, I32, F32]:
        """The (candidate row, cell, hits, nearest range) of every cell seen, by row and
        then cell."""
        counts, rng = table[3], table[4]
        k = np.flatnonzero(counts)
        q = np.searchsorted(starts, k, side="right") - 1
        rows, plots = owner[q, 0], owner[q, 1]
        cells = k - starts[q] + self.offset[plots]
        return rows, cells, counts[k], rng[k]


def cast_chunk(cast: Caster, s: int, e: int) -> Cast:
    """The pairs of candidates ``s`` to ``e`` (rows of ``cand_xy``), and the rays cast."""
    before = cast.rays
    pairs = cast(np.arange(s, e))
    return pairs, cast.rays - before


class Caster:
    """Casts the rays of chosen candidates (rows of ``cand_xy``) and keeps count of
    them: ``caster(rows)`` gives their pairs (cand, cell, hits, nearest range)."""

    def __init__(
        self,
        field: Field,
        scanner: ScannerModel,
        mode: str,
        samples: int,
        cull_sides: bool,
        step_deg: float | None,
    ) -> None:
        self.field, self.scanner, self.mode, self.samples = field, scanner, mode, samples
        self.grid = build_grid(field.plot_boxes)
        self.rays = 0
        if mode == "grid":
            self.dirs = grid_directions(scanner, step_deg)
        else:
            self.faces = exposed_faces(field)
            # planar occlusion (see services.planner.exact) holds when every plot
            # stands on the ground and reaches the optical centre
            b = self.grid.boxes
            self.cull = bool(np.all(b[:, 2] <= 0.0) and np.all(b[:, 5] >= scanner.height))
            self.cull = self.cull and cull_sides
        self.scratch = _Scratch(field, scanner.max_range)

    def __call__(self, rows: I64) -> Pairs:
        sc, g = self.scanner, self.grid
        o = np.column_stack([self.field.cand_xy[rows], np.full(len(rows), sc.height)])
        o = np.ascontiguousarray(o)
        table, starts, owner = self.scratch.table(o, self.field.cell_dims)
        if self.mode == "grid":
            _grid_kernel(o, self.dirs, sc.min_range, sc.max_range, g.args, table)
            self.rays += len(o) * len(self.dirs)
        else:
            hspan = sc.horizontal_end_deg - sc.horizontal_start_deg
            limits = (
                sc.min_range,
                sc.max_range,
                sc.vertical_start_deg,
                sc.vertical_end_deg,
                sc.horizontal_start_deg,
                hspan,
            )
            faces, fint, side_start = self.faces
            nr = exact_kernel(
                o, limits, self.samples, self.cull, faces, fint, side_start, g.args, table
            )
            self.rays += int(nr.sum())
        ci, ki, hits, near = self.scratch.pairs(table, starts, owner)
        return rows[ci].astype(np.int32), ki.astype(np.int32), hits.copy(), near.copy()
