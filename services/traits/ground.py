"""The ground under a survey: the cloth simulation filter on the registered cloud,
then a regular grid of ground heights (:class:`GroundModel`) that gives every point
its height above the ground.

Why a grid and not the filter's own classification: a plot's canopy hides the ground
under it, so the height of a canopy point must come from ground seen around the plot
(lanes, alleys, gaps between plants); the grid interpolates it there, smoothly, and is
also what two surveys of one field compare (:meth:`GroundModel.stable_mask`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import sys
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from common.arrays import F64
from services.traits.config import GroundConfig

B = npt.NDArray[np.bool_]


# heights of the ground in one field differ by less (m); see grid_ground
SPAN = 1024.0


class GroundError(ValueError):
    """No ground could be found in the cloud."""


@dataclasses.dataclass(frozen=True, eq=False)
class GroundModel:
    """Ground heights ``z`` (ny, nx) in square cells of ``cell`` metres, cell (i, j)
    centred at ``(x0 + (j + 0.5) cell, y0 + (i + 0.5) cell)`` (field frame);
    ``measured`` (ny, nx): the cells holding ground points (the others are filled
    from the nearest measured cell); ``count`` (ny, nx): ground points per cell."""

    x0: float
    y0: float
    cell: float
    z: F64
    measured: B
    count: npt.NDArray[np.int64]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.z.shape[0]), int(self.z.shape[1]))

    def centres(self) -> tuple[F64, F64]:
        """The cells' centre x (nx,) and y (ny,)."""
        ny, nx = self.shape
        x = self.x0 + (np.arange(nx, dtype=np.float64) + 0.5) * self.cell
        y = self.y0 + (np.arange(ny, dtype=np.float64) + 0.5) * self.cell
        return x, y

    def height(self, x: npt.ArrayLike, y: npt.ArrayLike) -> F64:
        """The ground's z at field-frame ``x``, ``y`` (any shape), bilinear between
        cell centres and constant beyond the outer centres."""
        ny, nx = self.shape
        u = np.clip((np.asarray(x, dtype=np.float64) - self.x0) / self.cell - 0.5, 0, nx - 1)
        v = np.clip((np.asarray(y, dtype=np.float64) - self.y0) / self.cell - 0.5, 0, ny - 1)
        coords = np.stack([v.ravel(), u.ravel()])
        z = ndimage.map_coordinates(self.z, coords, order=1, mode="nearest", prefilter=False)
        return np.asarray(z, dtype=np.float64).reshape(u.shape)

    def stable_mask(self, plot_boxes: F64, margin: float = 0.5) -> B:
        """(ny, nx) True for measured cells that lie, whole, more than ``margin``
        metres from every plot box (``[xmin, ymin, ...]`` with x at column 0 and
        3 or 0 and 2: (P, 6) field boxes or (P, 4) footprints): lanes and headlands,
        whose ground the crop does not change between two surveys."""
        boxes = np.asarray(plot_boxes, dtype=np.float64)
        hi = boxes.shape[1] // 2
        free = np.ones(self.shape, dtype=bool)
        ny, nx = self.shape
        for b in boxes:
            # cells whose square comes within margin of the box
            j0 = int(np.floor((b[0] - margin - self.x0) / self.cell))
            j1 = int(np.ceil((b[hi] + margin - self.x0) / self.cell))
            i0 = int(np.floor((b[1] - margin - self.y0) / self.cell))
            i1 = int(np.ceil((b[hi + 1] + margin - self.y0) / self.cell))
            free[max(i0, 0) : min(max(i1, 0), ny), max(j0, 0) : min(max(j1, 0), nx)] = False
        return free & self.measured


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """The filter's C++ code prints its progress on file descriptor 1, where the
    command's own result line goes: send it to /dev/null meanwhile."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no stdout at all
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def lowest_per_cell(xyz: F64, cell: float) -> F64:
    """The lowest point of every ``cell``-metre xy square holding points (M, 3; a
    square whose lowest z is shared by two points gives both)."""
    ij = np.floor((xyz[:, :2] - xyz[:, :2].min(axis=0)) / cell).astype(np.int64)
    n1 = int(ij[:, 1].max()) + 1
    key = ij[:, 0] * n1 + ij[:, 1]
    low = np.full(int(key.max()) + 1, np.inf)
    np.minimum.at(low, key, xyz[:, 2])  # no sort: a scatter is linear in the points
    return xyz[xyz[:, 2] == low[key]]


def cloth_filter(xyz: F64, cfg: GroundConfig) -> F64:
    """The points of ``xyz`` (N, 3) the cloth simulation filter classes as ground."""
    import CSF

    csf = CSF.CSF()
    csf.params.bSloopSmooth = cfg.slope_smooth
    csf.params.cloth_resolution = cfg.cloth_resolution
    csf.params.rigidness = cfg.rigidness
    csf.params.class_threshold = cfg.class_threshold
    csf.params.interations = cfg.iterations  # sic: the binding's spelling
    ground, off = CSF.VecInt(), CSF.VecInt()
    with _quiet_stdout():
        csf.setPointCloud(np.ascontiguousarray(xyz, dtype=np.float64))
        csf.do_filtering(ground, off, False)
    return xyz[np.asarray(ground, dtype=np.int64)]


def grid_ground(pts: F64, bounds: F64, cfg: GroundConfig, linear: bool = True) -> GroundModel:
    """The :class:`GroundModel` over ``bounds`` [xmin, ymin, xmax, ymax] from ground
    points ``pts`` (M, 3): median per cell, steps above the neighbourhood dropped,
    holes filled (:func:`_fill`; ``linear`` False: nearest cell only). Raises
    GroundError when no point falls in ``bounds``."""
    c = cfg.grid_cell
    nx = max(1, int(np.ceil((bounds[2] - bounds[0]) / c)))
    ny = max(1, int(np.ceil((bounds[3] - bounds[1]) / c)))
    j = np.floor((pts[:, 0] - bounds[0]) / c).astype(np.int64)
    i = np.floor((pts[:, 1] - bounds[1]) / c).astype(np.int64)
    keep = (j >= 0) & (j < nx) & (i >= 0) & (i < ny)
    if not keep.any():
        raise GroundError("no ground point inside the field")
    # one sort of (cell, z) packed in a float: the cell in the integer part, z
    # (relative, below SPAN metres) in the fraction; far faster than a lexsort
    z = pts[keep, 2]
    zlo = float(z.min())
    if float(z.max()) - zlo >= SPAN:
        raise GroundError(f"the ground spans more than {SPAN:g} m in height")
    packed = np.sort((i[keep] * nx + j[keep]) * SPAN + (z - zlo))
    key = (packed // SPAN).astype(np.int64)
    z = packed - key * SPAN + zlo
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    counts = np.diff(np.r_[starts, len(key)])
    # the median of a sorted run: the mean of its two middle values
    med = 0.5 * (z[starts + (counts - 1) // 2] + z[starts + counts // 2])
    grid = np.full((ny, nx), np.nan)
    grid.flat[key[starts]] = med
    count = np.zeros((ny, nx), dtype=np.int64)
    count.flat[key[starts]] = counts
    measured = np.isfinite(grid)
    # canopy the filter took for ground (a patch of a dense plot's top) stands out as
    # a step above the ground around it: drop it, the fill takes the neighbours'
    size = 2 * int(cfg.step_window / c / 2) + 1
    local = ndimage.median_filter(_fill(grid, measured, False), size=size, mode="nearest")
    measured &= ~(grid > local + cfg.max_step)
    return GroundModel(
        x0=float(bounds[0]),
        y0=float(bounds[1]),
        cell=c,
        z=_fill(grid, measured, linear),
        measured=measured,
        count=np.where(measured, count, 0),
    )


def _fill(grid: F64, measured: B, linear: bool = True) -> F64:
    """``grid`` with its unmeasured cells interpolated linearly between the measured
    ones around them (a plot's hidden ground lies on the plane of the lanes around
    it, which a nearest-cell fill would turn into steps as high as the slope times
    half the plot's width), and beyond them set to the nearest measured cell."""
    if measured.all():
        return grid.copy()
    idx = ndimage.distance_transform_edt(~measured, return_distances=False, return_indices=True)
    out = np.asarray(grid[tuple(idx)], dtype=np.float64)
    holes = np.argwhere(~measured)
    # only the measured cells bordering a hole shape it: triangulating those alone
    # keeps the fill fast on a large field
    known = np.argwhere(measured & ndimage.binary_dilation(~measured))
    if linear and len(known) >= 3 and len(holes):
        from scipy.interpolate import griddata
        from scipy.spatial import QhullError

        try:
            lin = griddata(known, grid[known[:, 0], known[:, 1]], holes, method="linear")
        except QhullError:  # measured cells on one line: no triangle to interpolate in
            return out
        ok = np.isfinite(lin)
        out[holes[ok, 0], holes[ok, 1]] = lin[ok]
    return out


def fit_ground(xyz: F64, bounds: F64, cfg: GroundConfig) -> GroundModel:
    """The ground of cloud ``xyz`` (N, 3, field frame) over ``bounds`` (see the
    module docstring); raises GroundError."""
    if len(xyz) == 0:
        raise GroundError("the cloud is empty")
    low = lowest_per_cell(xyz, cfg.reduce_cell)
    ground = cloth_filter(low, cfg) if len(low) >= 3 else low
    if len(ground) == 0:
        raise GroundError("the cloth filter found no ground")
    if cfg.refine_band <= 0:
        return grid_ground(ground, bounds, cfg)
    # the first pass only picks the points near the ground where ground was seen:
    # its holes need no interpolation
    first = grid_ground(ground, bounds, cfg, linear=False)
    # the lowest point of a cell sits below the surface by the range noise: take
    # every point of the cloud near that first ground instead, whose median does not
    near = np.abs(xyz[:, 2] - first.height(xyz[:, 0], xyz[:, 1])) <= cfg.refine_band
    return grid_ground(xyz[near], bounds, cfg) if near.any() else first
