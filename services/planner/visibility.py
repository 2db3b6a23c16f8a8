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
from collections.abc import Callable, Iterator
from typing import Any

import numba as nb
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

from common.field import Field, ScannerModel
from services.planner.exact import exact_kernel
from services.planner.faces import exposed_faces
from services.planner.lattice import lattice_of
from services.planner.lattice import translate as translate_pairs
from services.planner.raycast import GridArgs, Table, build_grid, cell_of, first_hit, record

log = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
I32 = npt.NDArray[np.int32]
F32 = npt.NDArray[np.float32]
Progress = Callable[[int, int], None]
Pairs = tuple[I32, I32, I32, F32]  # candidate, cell, hits, nearest range
# casts chunks (first, last + 1) of candidates with the options (mode, samples,
# cull_sides, step_deg) somewhere: (last + 1, (pairs, rays)) of each, in order
Cast = tuple[Pairs, int]  # a chunk's pairs and the rays cast for them
Chunks = Callable[[list[tuple[int, int]], tuple[Any, ...]], Iterator[tuple[int, Cast]]]


@dataclasses.dataclass(frozen=True, eq=False)
class Visibility:
    """Sparse visibility table. ``cand`` indexes ``Field.cand_xy`` (not the ids); 32-bit,
    as a field of thousands of plots has tens of millions of pairs. The pairs come by
    candidate, then by cell, as :func:`compute_visibility` gives them."""

    cand: I32
    cell: I32
    hits: I32
    range_min: F32  # metres from the optical centre to the nearest seen point
    n_candidates: int
    n_cells: int
    rays: int
    mode: str

    def matrix(self, min_hits: int = 1) -> sp.csr_matrix:
        """(candidates x cells) boolean CSR of pairs seen by at least ``min_hits``."""
        keep = self.hits >= min_hits
        # sorted by candidate and cell: the CSR arrays directly, no COO sort
        cand, cell = self.cand[keep], self.cell[keep]
        indptr = np.concatenate([[0], np.cumsum(np.bincount(cand, minlength=self.n_candidates))])
        data = np.ones(len(cell), dtype=bool)
        shape = (self.n_candidates, self.n_cells)
        return sp.csr_matrix((data, cell, indptr), shape=shape)

    def cell_min_range(self) -> F64:
        """Nearest range at which each cell is seen (inf where never)."""
        return _min_by_cell(self.cell, self.range_min, self.n_cells)

    def cell_views(self, min_hits: int = 1) -> I64:
        """Number of candidates that see each cell."""
        keep = self.hits >= min_hits
        return np.bincount(self.cell[keep], minlength=self.n_cells).astype(np.int64)


@nb.njit(cache=True)
def _min_by_cell(cell: I32, rng: F32, n: int) -> F64:  # pragma: no cover - compiled
    # np.minimum.at does this in 2.7 s for a 100 x 100-plot field's 36 M pairs
    out = np.full(n, np.inf)
    for k in range(len(cell)):
        if rng[k] < out[cell[k]]:
            out[cell[k]] = rng[k]
    return out


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
        b = self.boxes
        # the plots a candidate's range reaches: the nearest point of the box within rmax
        gx = np.maximum(
            np.maximum(b[None, :, 0] - o[:, None, 0], 0.0), o[:, None, 0] - b[None, :, 3]
        )
        gy = np.maximum(
            np.maximum(b[None, :, 1] - o[:, None, 1], 0.0), o[:, None, 1] - b[None, :, 4]
        )
        gz = np.maximum(
            np.maximum(b[None, :, 2] - o[:, None, 2], 0.0), o[:, None, 2] - b[None, :, 5]
        )
        near = gx * gx + gy * gy + gz * gz <= self.rmax * self.rmax
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
        then cell, as the dense table's ``np.nonzero`` gave them."""
        counts, rng = table[3], table[4]
        k = np.flatnonzero(counts)
        q = np.searchsorted(starts, k, side="right") - 1
        rows, plots = owner[q, 0], owner[q, 1]
        cells = k - starts[q] + self.offset[plots]
        return rows, cells, counts[k], rng[k]


def compute_visibility(
    field: Field,
    scanner: ScannerModel,
    mode: str = "exact",
    *,
    samples: int = 3,
    cull_sides: bool = True,
    step_deg: float | None = None,
    progress: Progress | None = None,
    translate: bool = True,
    chunks: Chunks | None = None,
) -> Visibility:
    """Visibility table of every candidate of ``field``.

    ``mode`` is ``"exact"`` (``samples`` x ``samples`` points per exposed cell face) or
    ``"grid"`` (``step_deg``, default the scanner's step). ``cull_sides`` skips plot
    sides that one box provably hides (same result, faster; off only to check that).
    ``translate``: a regular field's table from one candidate's (:mod:`.lattice`;
    off only to check that). ``chunks``: where a field cast candidate by candidate has
    its chunks cast (:class:`.cluster.DaskChunks`; default: here). ``progress(done,
    total)`` is called after each chunk of candidates. Raises ValueError on a bad mode
    or sampling.
    """
    if mode not in ("exact", "grid"):
        raise ValueError(f"visibility mode {mode!r}: expected 'exact' or 'grid'")
    if samples < 1:
        raise ValueError(f"samples={samples}: expected >= 1")
    n, t0 = field.n_candidates, time.perf_counter()
    lat = lattice_of(field, scanner.max_range) if translate else None
    cast = Caster(field, scanner, mode, samples, cull_sides, step_deg)
    if lat is None:
        ranges = [(s, min(n, s + CHUNK)) for s in range(0, n, CHUNK)]
        if chunks is None:
            parts: Iterator[tuple[int, Cast]] = ((e, cast_chunk(cast, s, e)) for s, e in ranges)
        else:
            parts = chunks(ranges, (mode, samples, cull_sides, step_deg))
        (cand, cell, hits, near), rays = _gather(parts, n, mode, progress)
    else:
        _, one, h1, r1 = cast(np.array([lat.template]))
        rays = cast.rays
        cand, cell, hits, near = translate_pairs(field, lat, one, h1, r1, progress)
        log.info(
            "visibility (%s): a regular field, candidate %d's %d pairs moved to every "
            "candidate, %.1f s", mode, lat.template, len(one), time.perf_counter() - t0,
        )  # fmt: skip
    return Visibility(cand, cell, hits, near, n, field.n_cells, rays, mode)


def cast_chunk(cast: Caster, s: int, e: int) -> Cast:
    """The pairs of candidates ``s`` to ``e`` (rows of ``cand_xy``), and the rays cast."""
    before = cast.rays
    pairs = cast(np.arange(s, e))
    return pairs, cast.rays - before


def _gather(
    parts: Iterator[tuple[int, Cast]], n: int, mode: str, progress: Progress | None
) -> Cast:
    """The chunks' pairs, in order, into one table, and the rays cast; ``parts``
    yields (candidates done, (pairs, rays)) chunk by chunk."""
    got: list[Pairs] = []
    rays = 0
    t0 = last_log = time.perf_counter()
    for e, (part, r) in parts:
        got.append(part)
        rays += r
        now = time.perf_counter()
        if now - last_log > 2.0 or e == n:
            log.info("visibility (%s): %d/%d candidates, %.1f s", mode, e, n, now - t0)
            last_log = now
        if progress is not None:
            progress(e, n)
    if not got:
        zeros = np.zeros(0, np.int32)
        return (zeros, zeros, zeros, np.zeros(0, np.float32)), rays
    cand, cell, hits, near = (np.concatenate([p[i] for p in got]) for i in range(4))
    return (cand, cell, hits, near), rays


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
