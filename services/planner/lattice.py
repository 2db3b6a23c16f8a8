"""Visibility of a regular field by translation.

A field built from a layout (identical plots at one pitch along x and one along y,
the candidates at lane intersections, :func:`common.field.build_field`) looks the
same from every candidate: the plot ``dr`` rows and ``dc`` columns away from the
candidate at lane intersection (r, c) is seen, cell for cell, as the plot ``dr``, ``dc``
away from any other candidate. What could differ is what stands between them, and
that is the same too: a line of sight from a candidate to a plot of the field stays
within the field's outer lanes, so a plot the field lacks beyond its edge is never in
its way, and one beyond the scanner's range is not either.

So the visibility of one candidate whose range lies inside the field (the
*template*) gives every candidate's: its pairs, moved by each candidate's lane
offset, keeping the plots that exist. On a 100 x 100-plot field that is one
candidate cast instead of 10,201. A field that is not such a lattice (a GeoJSON of
measured plots, the crop as measured), or too small to hold a whole range inside it,
is cast candidate by candidate (:mod:`.visibility`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numba as nb
import numpy as np

from common.arrays import F32, I32, I64
from common.field import Field

_TOL = 1e-9  # metres: a lattice's boxes and lanes agree to this


@dataclasses.dataclass(frozen=True)
class Lattice:
    """Plot ``plot_at[row, col]``; the template candidate (a row of ``cand_xy``)."""

    plot_at: I64
    template: int


def lattice_of(field: Field, reach: float) -> Lattice | None:
    """The lattice of ``field`` when it is one and some candidate has every plot
    within ``reach`` metres inside it; else None."""
    b, row, col = field.plot_boxes, field.plot_row, field.plot_col
    nr, nk = int(row.max()) + 1, int(col.max()) + 1
    if len(b) != nr * nk or not np.all(field.cell_dims == field.cell_dims[0]):
        return None
    plot_at = np.full((nr, nk), -1, dtype=np.int64)
    plot_at[row, col] = np.arange(len(b))
    if np.any(plot_at < 0) or np.any(np.diff(plot_at.ravel()) <= 0):
        return None  # a lattice position twice, or plots not numbered row by row
    px = (b[plot_at[0, 1], 0] - b[plot_at[0, 0], 0]) if nk > 1 else 0.0
    py = (b[plot_at[1, 0], 1] - b[plot_at[0, 0], 1]) if nr > 1 else 0.0
    shift = np.zeros_like(b)
    shift[:, [0, 3]] = (col * px)[:, None]
    shift[:, [1, 4]] = (row * py)[:, None]
    if np.abs(b - shift - b[plot_at[0, 0]]).max() > _TOL:
        return None
    xs, ys = field.cross_lanes_x, field.row_lanes_y
    if np.abs(np.diff(xs) - px).max(initial=0.0) > _TOL:
        return None
    if np.abs(np.diff(ys) - py).max(initial=0.0) > _TOL:
        return None
    if not (px > 0 and py > 0):
        return None
    # the template: the candidate nearest the middle whose range holds no plot row or
    # column beyond the field's
    span_x = b[0, 3] - b[0, 0]
    span_y = b[0, 4] - b[0, 1]
    need_c = math.ceil((reach + span_x) / px) + 1
    need_r = math.ceil((reach + span_y) / py) + 1
    r, c = field.cand_row_lane, field.cand_cross_lane
    inside = (r - need_r >= 0) & (r + need_r <= nr) & (c - need_c >= 0) & (c + need_c <= nk)
    if not inside.any():
        return None
    mid = (r - nr / 2) ** 2 + (c - nk / 2) ** 2
    return Lattice(plot_at, int(np.flatnonzero(inside)[np.argmin(mid[inside])]))


def translate(
    field: Field,
    lat: Lattice,
    cell: I32,
    hits: I32,
    rng: F32,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[I32, I32, I32, F32]:
    """The template's pairs (``cell``, ``hits``, ``rng``, by cell) moved to every
    candidate: (cand, cell, hits, nearest range), by candidate and then cell as a
    cast gives them. ``progress(done, total)`` after each block of candidates."""
    t = lat.template
    per = int(field.cell_offset[1] - field.cell_offset[0])
    p = cell.astype(np.int64) // per  # plots numbered row by row, the same cells each
    local = cell - p * per
    dr = field.plot_row[p] - field.cand_row_lane[t]
    dc = field.plot_col[p] - field.cand_cross_lane[t]
    nr, nk = lat.plot_at.shape
    rows, cols = field.cand_row_lane, field.cand_cross_lane
    counts = _count(rows, cols, dr, dc, nr, nk)
    start = np.concatenate([[0], np.cumsum(counts)])
    total = int(start[-1])
    out = (
        np.empty(total, np.int32),
        np.empty(total, np.int32),
        np.empty(total, np.int32),
        np.empty(total, np.float32),
    )
    n = field.n_candidates
    for s in range(0, n, _BLOCK):
        e = min(n, s + _BLOCK)
        _fill(s, e, start, rows, cols, dr, dc, nr, nk, local, per, hits, rng, out)
        if progress is not None:
            progress(e, n)
    return out


_BLOCK = 1024  # candidates between progress reports


@nb.njit(parallel=True, cache=True)
def _count(
    rows: I64, cols: I64, dr: I64, dc: I64, nr: int, nk: int
) -> I64:  # pragma: no cover - compiled
    """Template pairs whose plot exists, per candidate."""
    out = np.zeros(len(rows), dtype=np.int64)
    for a in nb.prange(len(rows)):
        k = 0
        for j in range(len(dr)):
            r, c = rows[a] + dr[j], cols[a] + dc[j]
            if 0 <= r < nr and 0 <= c < nk:
                k += 1
        out[a] = k
    return out


@nb.njit(parallel=True, cache=True)
def _fill(
    s: int, e: int, start: I64, rows: I64, cols: I64, dr: I64, dc: I64, nr: int,
    nk: int, local: I64, per: int, hits: I32, rng: F32, out: tuple[I32, I32, I32, F32],
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """Candidates s..e's pairs, each from its ``start``; the plot at (row, col) is
    ``row * nk + col`` (:func:`lattice_of` checks it)."""
    cand, cell, h, near = out
    for a in nb.prange(s, e):
        k = start[a]
        for j in range(len(dr)):
            r, c = rows[a] + dr[j], cols[a] + dc[j]
            if r < 0 or c < 0 or r >= nr or c >= nk:
                continue
            cand[k] = a
            cell[k] = (r * nk + c) * per + local[j]
            h[k] = hits[j]
            near[k] = rng[j]
            k += 1
