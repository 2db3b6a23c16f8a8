"""The crop as a survey measured it: per plot its canopy box and which of its planner
columns hold canopy, so the next survey can be planned on the field as it stands
(``services/planner/measured.py``) instead of on nominal plot boxes.

Input: canopy points in the ``field`` frame (x, y) with their height above the ground h
(metres), as the traits step has them (:mod:`common.canopy` defines what canopy is:
``h >= min_height``). A point belongs to the plot whose nominal footprint holds it, or,
in a lane, to the nearest plot within ``margin`` (a plant leaning out of its plot). As
a lane point goes to the *nearest* plot, a plot's measured extent stops at the middle of
the lane and never reaches the next plot's nominal box.

Per plot: ``box`` = [xmin, ymin, xmax, ymax, height] (the xy extent of its canopy
points, height their 99th percentile of h) and ``columns``: the flat indices
``ix * ny + iy`` of its nominal voxel columns (the planner's ``voxel_x`` x ``voxel_y``
grid of the nominal box, ``grid`` = (nx, ny)) that hold canopy; a plot without canopy
has ``box`` None and no columns.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import msgspec
import numba as nb
import numpy as np
import numpy.typing as npt

from common.arrays import F64, I64
from common.field import Field, FieldLayout
from common.files import write_atomic
from common.messages.core import Coordinate

HEIGHT_PERCENTILE = 99.0
MAX_FILE_BYTES = 64 << 20
Length = Annotated[float, msgspec.Meta(ge=0.0, le=1e4)]
# a box in the field frame (m): x0, y0, x1, y1, height
Box = tuple[Coordinate, Coordinate, Coordinate, Coordinate, Length]


class CropModelError(ValueError):
    """A crop model cannot be read or does not fit the field; one line."""


class PlotCanopy(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One plot's measured canopy: ``box`` [xmin, ymin, xmax, ymax, height] (m, field
    frame; None: no canopy point), ``grid`` its nominal columns (nx, ny), ``columns``
    the occupied ones (``ix * ny + iy``, ascending), ``points`` its canopy points."""

    box: Box | None
    grid: tuple[Annotated[int, msgspec.Meta(ge=1)], Annotated[int, msgspec.Meta(ge=1)]]
    columns: tuple[Annotated[int, msgspec.Meta(ge=0)], ...] = ()
    points: Annotated[int, msgspec.Meta(ge=0)] = 0

    def __post_init__(self) -> None:
        n = self.grid[0] * self.grid[1]
        if any(c >= n for c in self.columns):
            raise ValueError(f"a column index is outside the plot's {n} columns")
        if self.box is not None and (self.box[2] < self.box[0] or self.box[3] < self.box[1]):
            raise ValueError(f"box {list(self.box)} has max < min")


class CropModel(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The field ``field`` as surveyed on ``date`` ("" = unknown): ``cell`` the column
    size (voxel_x, voxel_y) the columns were counted in, ``margin`` how far into the
    lanes points were given to a plot, ``min_height`` the canopy threshold; ``plots``
    in the field's plot order."""

    field: str
    date: str = ""
    cell: tuple[Length, Length]
    margin: Length
    min_height: Length
    plots: tuple[PlotCanopy, ...]

    def boxes(self) -> F64:
        """(P, 5) [xmin, ymin, xmax, ymax, height]; NaN rows for plots without canopy."""
        out = np.full((len(self.plots), 5), np.nan)
        for p, pc in enumerate(self.plots):
            if pc.box is not None:
                out[p] = pc.box
        return out


def by_plot(plot: I64, n: int) -> tuple[I64, I64]:
    """The points of each of ``n`` plots together, from each point's ``plot`` (-1
    none): ``order`` (the points with a plot, by plot, in their order within one) and
    ``starts`` (n + 1,): plot k's points are ``order[starts[k]:starts[k + 1]]``."""
    inside = np.flatnonzero(plot >= 0)
    order = inside[np.argsort(plot[inside], kind="stable")]
    starts = np.concatenate([[0], np.cumsum(np.bincount(plot[inside], minlength=n))])
    return order, starts.astype(np.int64)


def assign_plots(xy: F64, boxes: F64, row: I64, col: I64, margin: float) -> I64:
    """The plot (index into ``boxes`` (P, >=5) [xmin, ymin, ..., xmax, ymax, ...]) of
    every point (N, 2): the one whose footprint holds it, else the nearest within
    ``margin``; -1 for none.

    A field's plots lie in row bands (y) and column bands (x) that do not overlap
    (:func:`common.field.assemble` checks it), so a point's nearest plots are among
    the 2 x 2 around the bands it falls in or between: O(N log P), no N x P table.
    """
    lo = np.ascontiguousarray(boxes[:, [0, 1]], dtype=np.float64)
    hi = np.ascontiguousarray(boxes[:, [3, 4]], dtype=np.float64)
    row_lo, col_lo, table = plot_bands(boxes, row, col)
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    k = np.searchsorted(row_lo, xy[:, 1], side="right") - 1
    j = np.searchsorted(col_lo, xy[:, 0], side="right") - 1
    return _nearest_of_four(xy, k, j, table, lo, hi, float(margin))


def plot_bands(boxes: F64, row: I64, col: I64) -> tuple[F64, F64, I64]:
    """How a point's plot is found: each row band's lower y (R,), each column band's
    lower x (C,) and the plot in each (row, column) band (R, C; -1 none)."""
    nrows, ncols = int(row.max()) + 1, int(col.max()) + 1
    table = np.full((nrows, ncols), -1, dtype=np.int64)
    table[row, col] = np.arange(len(boxes))
    row_lo = np.array([boxes[row == r, 1].min() for r in range(nrows)])
    col_lo = np.array([boxes[col == c, 0].min() for c in range(ncols)])
    return row_lo, col_lo, table


@nb.njit(cache=True, error_model="numpy")
def _nearest_of_four(
    xy: F64, k: I64, j: I64, table: npt.NDArray[np.int64], lo: F64, hi: F64, margin: float
) -> I64:  # pragma: no cover - compiled
    """Per point, the nearest of the plots in bands (k, j) .. (k + 1, j + 1) within
    ``margin`` (the first in that order on a tie), else -1; one pass over the points,
    where numpy would make four over arrays of them."""
    nrows, ncols = table.shape
    out = np.full(len(xy), -1, dtype=np.int64)
    for i in range(len(xy)):
        best_d = np.inf
        for dk in range(2):
            r = k[i] + dk
            if r < 0 or r >= nrows:
                continue
            for dj in range(2):
                c = j[i] + dj
                if c < 0 or c >= ncols:
                    continue
                p = table[r, c]
                if p < 0:
                    continue
                gx = max(lo[p, 0] - xy[i, 0], xy[i, 0] - hi[p, 0], 0.0)
                gy = max(lo[p, 1] - xy[i, 1], xy[i, 1] - hi[p, 1], 0.0)
                d = np.hypot(gx, gy)
                if d < best_d:
                    best_d = d
                    if d <= margin:
                        out[i] = p
    return out


def crop_model(
    xy: F64,
    h: F64,
    field: Field,
    layout: FieldLayout,
    *,
    margin: float = 0.3,
    min_height: float = 0.05,
    date: str = "",
) -> CropModel:
    """The crop model of ``field`` from points ``xy`` (N, 2, field frame) at heights
    ``h`` (N,) above the ground; points lower than ``min_height`` (ground) are ignored.
    Raises ValueError on mismatched or non-finite input."""
    xy, h = np.asarray(xy, dtype=np.float64), np.asarray(h, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or h.shape != (len(xy),):
        raise ValueError(f"crop_model: expected xy (N, 2) and h (N,), got {xy.shape}, {h.shape}")
    if not 0.0 <= margin <= 10.0 or not 0.0 <= min_height <= 10.0:
        raise ValueError(f"crop_model: margin={margin}, min_height={min_height}: 0-10 m expected")
    keep = np.isfinite(h) & np.all(np.isfinite(xy), axis=1) & (h >= min_height)
    xy, h = xy[keep], h[keep]
    boxes = field.plot_boxes
    plot = assign_plots(xy, boxes, field.plot_row, field.plot_col, margin)
    own = plot >= 0
    xy, h, plot = xy[own], h[own], plot[own]
    n_plots = field.n_plots
    grid = field.cell_dims[:, :2]
    occupied = _occupied_columns(xy, plot, boxes, grid)

    lo = np.full((n_plots, 2), np.inf)
    hi = np.full((n_plots, 2), -np.inf)
    np.minimum.at(lo, plot, xy)
    np.maximum.at(hi, plot, xy)
    order, starts = by_plot(plot, n_plots)
    count = np.diff(starts)
    h_sorted = h[order]
    plots = []
    for p in range(n_plots):
        nx, ny = int(grid[p, 0]), int(grid[p, 1])
        if count[p] == 0:
            plots.append(PlotCanopy(box=None, grid=(nx, ny)))
            continue
        top = float(np.percentile(h_sorted[starts[p] : starts[p + 1]], HEIGHT_PERCENTILE))
        box = (float(lo[p, 0]), float(lo[p, 1]), float(hi[p, 0]), float(hi[p, 1]), top)
        cols = tuple(int(c) for c in np.flatnonzero(occupied[p]))
        plots.append(PlotCanopy(box=box, grid=(nx, ny), columns=cols, points=int(count[p])))
    return CropModel(
        field=field.name,
        date=date,
        cell=(layout.voxel_x, layout.voxel_y),
        margin=margin,
        min_height=min_height,
        plots=tuple(plots),
    )


def _occupied_columns(xy: F64, plot: I64, boxes: F64, grid: I64) -> list[npt.NDArray[np.bool_]]:
    """Per plot, a flag per nominal column (nx * ny) for holding a point of ``xy``
    inside the plot's nominal footprint (points outside it lean into a lane)."""
    b = boxes[plot]
    inside = np.all((xy >= b[:, [0, 1]]) & (xy <= b[:, [3, 4]]), axis=1)
    xy, plot, b = xy[inside], plot[inside], b[inside]
    n = grid[plot]
    # columns as assemble cuts them: the box split evenly into nx x ny
    size = (b[:, [3, 4]] - b[:, [0, 1]]) / n
    ix = np.clip(((xy[:, 0] - b[:, 0]) / size[:, 0]).astype(np.int64), 0, n[:, 0] - 1)
    iy = np.clip(((xy[:, 1] - b[:, 1]) / size[:, 1]).astype(np.int64), 0, n[:, 1] - 1)
    per_plot = grid[:, 0] * grid[:, 1]
    offset = np.concatenate([[0], np.cumsum(per_plot)])
    flags = np.zeros(int(offset[-1]), dtype=bool)
    flags[offset[plot] + ix * n[:, 1] + iy] = True
    return [flags[offset[p] : offset[p + 1]] for p in range(len(boxes))]


def write(path: str | Path, model: CropModel) -> None:
    """Write ``model`` as JSON to ``path`` atomically (a reader never sees half a file)."""
    data = msgspec.json.encode(model)
    write_atomic(Path(path), data)


def read(path: str | Path, field: Field | None = None) -> CropModel:
    """The crop model in ``path``; with ``field``, checked to be a model of it (name,
    plot count, column grids). Raises CropModelError (one line)."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise CropModelError(f"{path}: more than {MAX_FILE_BYTES:,} bytes, not a crop model")
        data = path.read_bytes()
    except FileNotFoundError:
        raise CropModelError(f"{path}: no crop model") from None
    except OSError as exc:
        raise CropModelError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        model = msgspec.json.decode(data, type=CropModel)
    except msgspec.DecodeError as exc:
        raise CropModelError(f"{path}: not a crop model: {' '.join(str(exc).split())}") from None
    if field is not None:
        check(model, field, str(path))
    return model


def check(model: CropModel, field: Field, source: str = "crop model") -> None:
    """Raise CropModelError unless ``model`` describes ``field``'s plots and columns."""
    if model.field != field.name or len(model.plots) != field.n_plots:
        raise CropModelError(
            f"{source}: a crop model of field {model.field!r} ({len(model.plots)} plots), "
            f"not of field {field.name!r} ({field.n_plots} plots)"
        )
    grids = np.array([pc.grid for pc in model.plots], dtype=np.int64).reshape(-1, 2)
    if not np.array_equal(grids, field.cell_dims[:, :2]):
        raise CropModelError(
            f"{source}: its plots' column grids differ from field {field.name!r}'s "
            f"(measured with {model.cell[0]:g} x {model.cell[1]:g} m columns)"
        )
