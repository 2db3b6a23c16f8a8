"""A plot's occupied voxels as a survey's rays estimate them, voxels hidden behind
foliage included.

A scanner in the lanes sees a canopy's surface; its inside, and its far side from
where no scan stood, stay dark. Counting only the voxels that hold a return measures
the surface, a fraction of a row crop's occupied voxels. So every voxel of the
definition's lattice (:func:`common.canopy.plot_traits`: ``voxel`` cubes from the
plot's corner, layers by height above the ground) is one of three, as in occupancy
mapping (OctoMap's occupied, free and unknown):

- *hit*: it holds a canopy return;
- *passed*: a ray crossed it on its way to a return beyond, so it is (mostly) empty;
  a gap where plants failed to emerge, seen through, stays empty;
- *hidden*: neither. A hidden voxel inside the convex hull of the plot's canopy is
  counted as occupied: what kept every ray out of it is foliage in front, and a
  canopy dense enough for that is dense behind it too. Hidden voxels outside the
  hull are air no scan looked at, and are not counted. A voxel is inside when its
  centre is within half a voxel of the hull (the voxel reaches into it: a canopy's
  edge seen from no scan, such as a plot's end, still fills the voxels it cuts).

Where a plot was seen from one lane only, its far side is dark up to the hull that
the rest of the plot's canopy spans, whatever stands there. So the count is taken
over the plot's slices seen from both lanes (slices one voxel long, across the row;
seen by the ``seen`` trait's test, :func:`common.canopy.both_sides`: a point in the
outer third on each side) and carried to its whole length: the seen slices' mean
times the plot's slices, the ratio estimate of a partly observed plot. A plot seen
so over less than ``min_seen`` of these voxel-long slices keeps the count over all
its slices: a few slices carried to its length would say more than they hold. (The
``occluded`` flag compares the ``seen`` trait, over ``cell``-long slices, with the same
``min_seen``: the two shares are close but not the same.) Never fewer voxels than
hold a return.

The rays are walked from each scan's scanner position to each point of it in steps
of half a voxel (:func:`_walk`), compiled, on every core.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from common.arrays import F64, I64, Bool
from common.canopy import MAX_HEIGHT_M, CanopyDefinition, both_sides, footprint_cells, row_axis
from common.cropmodel import plot_bands
from common.field import Field
from services.traits.ground import GroundModel
from services.traits.run import Views


def occupied_voxels(
    xyz: F64, h: F64, groups: tuple[I64, I64], views: Views, keep: Bool, field: Field,
    ground: GroundModel, d: CanopyDefinition, min_seen: float,
) -> F64:  # fmt: skip
    """Per plot, its occupied voxels as the survey estimates them (see the module
    docstring): ``xyz`` (N, 3) the points (``keep`` of the run's cloud, whose
    ``views`` say where each was seen from), ``h`` their heights above the ground,
    ``groups`` each plot's points (:func:`common.cropmodel.by_plot`)."""
    boxes = field.plot_boxes[:, [0, 1, 3, 4]]
    dims = np.array([footprint_cells(b, d.voxel) for b in boxes], dtype=np.int64)
    canopy = h >= d.min_height
    top = min(MAX_HEIGHT_M, float(h[canopy].max(initial=0.0)))
    layers = math.ceil(top / d.voxel) + 1
    per_plot = dims[:, 0] * dims[:, 1] * layers
    offset = np.concatenate([[0], np.cumsum(per_plot)]).astype(np.int64)
    passed = np.zeros(int(offset[-1]), dtype=np.bool_)
    row_lo, col_lo, table = plot_bands(field.plot_boxes, field.plot_row, field.plot_col)
    _walk(
        np.ascontiguousarray(xyz), np.ascontiguousarray(views.source[keep]),
        np.ascontiguousarray(views.origins), ground.z, ground.x0, ground.y0, ground.cell,
        row_lo, col_lo, table, np.ascontiguousarray(boxes), dims, offset, layers, d.voxel,
        passed,
    )  # fmt: skip
    order, starts = groups
    gxy, gh, gcanopy = xyz[order, :2], h[order], canopy[order]  # grouped by plot
    out = np.zeros(len(boxes))
    for k in range(len(boxes)):
        mine = slice(starts[k], starts[k + 1])
        grid = passed[offset[k] : offset[k + 1]].reshape(dims[k, 0], dims[k, 1], layers)
        hit, occupied = _occupied(gxy[mine], gh[mine], gcanopy[mine], boxes[k], grid, d.voxel)
        counted = _over_seen_slices(occupied, gxy[mine], boxes[k], d.voxel, min_seen)
        out[k] = max(counted, float(hit.sum()))
    return out


def _occupied(xy: F64, h: F64, canopy: Bool, box: F64, passed: Bool, v: float) -> tuple[Bool, Bool]:
    """One plot's voxels (``passed``'s shape (nx, ny, nz)) holding a canopy point
    (``xy``, ``h`` where ``canopy``; heights above the lattice in its top layer), and
    those with the ones neither hit nor passed reaching into the hull of its canopy
    points (centre within half a voxel of it): (hit, occupied)."""
    from scipy.spatial import ConvexHull, QhullError

    nx, ny, nz = passed.shape
    hit = np.zeros_like(passed)
    xy, h = xy[canopy], h[canopy]
    ix = np.clip(np.floor((xy[:, 0] - box[0]) / v).astype(np.int64), 0, nx - 1)
    iy = np.clip(np.floor((xy[:, 1] - box[1]) / v).astype(np.int64), 0, ny - 1)
    iz = np.clip(np.floor(h / v).astype(np.int64), 0, nz - 1)
    hit[ix, iy, iz] = True
    if len(h) < 4:
        return hit, hit
    try:
        hull = ConvexHull(np.column_stack([xy, h]))
    except QhullError:  # flat or too few: no inside to hide anything
        return hit, hit
    dark = np.argwhere(~hit & ~passed)
    centre = (dark + 0.5) * v + np.array([box[0], box[1], 0.0])
    inside = np.all(centre @ hull.equations[:, :3].T + hull.equations[:, 3] <= 0.5 * v, axis=1)
    occupied = hit.copy()
    occupied[tuple(dark[inside].T)] = True
    return hit, occupied


def _over_seen_slices(occupied: Bool, xy: F64, box: F64, v: float, min_seen: float) -> float:
    """The occupied voxels of a plot's slices seen from both lanes (by its points
    ``xy``, canopy and ground), times the plot's slices over those: the ratio estimate
    over the whole plot; those of all its slices when under ``min_seen`` of them (or
    none) were seen from both."""
    axis = row_axis(box)
    n = occupied.shape[axis]
    along = np.clip(np.floor((xy[:, axis] - box[axis]) / v).astype(np.int64), 0, n - 1)
    seen = both_sides(along, xy[:, 1 - axis], box[1 - axis], box[3 - axis], n)
    per_slice = occupied.sum(axis=(1, 2) if axis == 0 else (0, 2))
    if not seen.any() or seen.mean() < min_seen:
        return float(per_slice.sum())
    return float(per_slice[seen].sum() * n / seen.sum())


@nb.njit(parallel=True, cache=True, error_model="numpy")
def _walk(
    pts: F64, source: I64, origins: F64, gz: F64, gx0: float, gy0: float, gcell: float,
    row_lo: F64, col_lo: F64, table: I64, boxes: F64, dims: I64, offset: I64,
    layers: int, v: float, passed: Bool,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """Mark in ``passed`` every voxel of a plot's lattice that a ray from
    ``origins[source[i]]`` to ``pts[i]`` crosses, up to half a voxel before the point.
    Threads may mark one voxel at once; they all write True."""
    gny, gnx = gz.shape
    nrows, ncols = table.shape
    step = 0.5 * v
    for i in nb.prange(len(pts)):
        o = origins[source[i]]
        dx, dy, dz = pts[i, 0] - o[0], pts[i, 1] - o[1], pts[i, 2] - o[2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        for s in range(1, int(length / step)):
            t = s * step / length
            x, y, z = o[0] + t * dx, o[1] + t * dy, o[2] + t * dz
            r = np.searchsorted(row_lo, y, side="right") - 1
            c = np.searchsorted(col_lo, x, side="right") - 1
            if r < 0 or c < 0 or r >= nrows or c >= ncols or table[r, c] < 0:
                continue
            p = table[r, c]
            ix = math.floor((x - boxes[p, 0]) / v)
            iy = math.floor((y - boxes[p, 1]) / v)
            if ix < 0 or iy < 0 or ix >= dims[p, 0] or iy >= dims[p, 1]:
                continue  # in the band, not in the plot (a lane between plots)
            gj = min(max(int((x - gx0) / gcell), 0), gnx - 1)
            gi = min(max(int((y - gy0) / gcell), 0), gny - 1)
            iz = math.floor((z - gz[gi, gj]) / v)
            if 0 <= iz < layers:
                passed[offset[p] + (ix * dims[p, 1] + iy) * layers + iz] = True
