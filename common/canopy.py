"""What a plot's canopy traits are: one definition, applied to the points a survey
measured (``services/traits``) and to the simulator's plants (``services/sim``), so a
trait and its truth differ only by what the scanner saw.

Every trait is computed from points given as field-frame x, y and height above the
ground h (metres), cut to one plot's footprint ``[xmin, ymin, xmax, ymax]``. A point
with ``h >= min_height`` is canopy, lower ones are ground. The plot's long side is
its planted row, cut along into *slices* ``cell`` metres long; the footprint is cut
into square ``cell`` cells for the canopy height model.

- the *canopy height model* (CHM): in every cell holding canopy, the highest canopy
  point's h (Jimenez-Berni et al. 2018, Front. Plant Sci. 9:237);
- ``height``: the ``height_percentile`` (99th) of the CHM over canopy cells, with
  ``height_p50`` and ``height_max`` beside it;
- ``cover``: projected cover, the area of the convex hull of the canopy points in
  plan view over the footprint's area (0-1; PlantCV's convex-hull area, on the
  ground plane);
- ``volume_voxel``: occupied ``voxel``-metre cubes of canopy (heights counted from
  the ground, so voxels follow the terrain) times the cube's volume; a survey's
  traits count the cubes hidden behind foliage inside the canopy's hull too, which no
  ray reached, over the part of the plot seen from both lanes
  (``services/traits/hidden.py``; the simulator's truth knows every cube);
- ``volume_hull``: the convex hull of the canopy points (x, y, h);
- ``points``: points in the footprint; ``seen``: the share of the slices holding a
  point (canopy or ground) in the outer third of the footprint on *both* sides of the
  row, i.e. seen from both lanes; the traits step flags a plot seen too little.

A ground scanner in the lanes sees a row crop from its sides, often at a grazing
angle, rarely from above (the FARO stands 1 m high beside canopies up to 1.9 m): the
hulls need only the canopy's outermost points, so they measure the plant; voxel
occupancy of the returns alone counts the surfaces the scanner saw, hence the hidden
cubes above (docs/traits.md). Hulls are taken of points as given:
the simulator's truth gives each foliage voxel's faces, the scanner the surfaces it
hit.
"""

from __future__ import annotations

import math
from typing import Annotated

import msgspec
import numpy as np

from common.arrays import F64, I64, Bool

# trait name -> unit, in the order the field book's columns list them
TRAITS: dict[str, str] = {
    "height": "m",
    "height_p50": "m",
    "height_max": "m",
    "cover": "1",
    "volume_voxel": "m3",
    "volume_hull": "m3",
    "points": "1",
    "seen": "1",
}
# traits.csv's field-book columns, first (services/traits writes the file, the
# dashboard and the evaluation read it)
BOOK_COLUMNS = ("plot", "row", "column", "rep", "entry")


def column(trait: str) -> str:
    """The traits files' column of ``trait``, its unit in the header: ``height (m)``."""
    return f"{trait} ({TRAITS[trait]})"


Cell = Annotated[float, msgspec.Meta(ge=0.005, le=1.0)]


# the highest a survey walks its rays and counts voxels above the ground (m): the
# lattice's memory, for the finest voxel allowed
MAX_HEIGHT_M = 10.0


class CanopyDefinition(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The definitions' parameters (metres; a percentile in 0-100)."""

    cell: Cell = 0.05
    """Canopy height model cells and slices along the row."""
    voxel: Annotated[float, msgspec.Meta(ge=0.05, le=1.0)] = 0.1
    """The occupancy volume's voxels (a survey walks every ray through a lattice of
    them up to ``MAX_HEIGHT_M`` above the ground: finer ones would fill the memory)."""
    min_height: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.05
    """Points lower than this above the ground are ground."""
    height_percentile: Annotated[float, msgspec.Meta(ge=50.0, le=100.0)] = 99.0
    """The percentile of the canopy height model a plot's height is."""

    def method(self, trait: str) -> str:
        """How ``trait`` is computed, in words (the long-format CSV's ``method``)."""
        c, v, m = self.cell * 100, self.voxel * 100, self.min_height * 100
        return {
            "height": f"p{self.height_percentile:g} of the canopy height model "
            f"({c:g} cm cells, canopy >= {m:g} cm above ground)",
            "height_p50": f"p50 of the canopy height model ({c:g} cm cells)",
            "height_max": f"max of the canopy height model ({c:g} cm cells)",
            "cover": "convex hull of the canopy in plan view, over the plot area",
            "volume_voxel": f"occupied {v:g} cm voxels of canopy, terrain-following "
            "(a survey with its scans' positions: those holding a return, and those "
            f"inside the canopy's hull that no ray reached, over the {v:g} cm slices seen "
            "from both sides of the row, per slice times the plot's slices; over all "
            "slices when fewer than min_seen of them were seen so)",
            "volume_hull": "convex hull of the canopy points",
            "points": "points inside the plot footprint",
            "seen": f"{c:g} cm slices with points on both sides of the row",
        }[trait]


def footprint_cells(box: F64, cell: float) -> tuple[int, int]:
    """Cells (nx, ny) of a footprint ``[xmin, ymin, xmax, ymax]``."""
    return (
        max(1, math.ceil((box[2] - box[0]) / cell - 1e-9)),
        max(1, math.ceil((box[3] - box[1]) / cell - 1e-9)),
    )


def row_axis(box: F64) -> int:
    """The axis (0: x, 1: y) a footprint ``[xmin, ymin, xmax, ymax]``'s planted row
    runs along: its long side."""
    return 0 if (box[2] - box[0]) >= (box[3] - box[1]) else 1


def both_sides(along: I64, across: F64, lo: float, hi: float, n: int) -> Bool:
    """Which of ``n`` slices along a row hold a point in the outer third of the row's
    width ``lo``..``hi`` on each side (seen from both lanes): points given by their
    slice ``along`` and their coordinate ``across`` the row."""
    third = (hi - lo) / 3
    near = np.bincount(along[across < lo + third], minlength=n)[:n] > 0
    far = np.bincount(along[across > hi - third], minlength=n)[:n] > 0
    return near & far


def plot_traits(
    xy: F64, h: F64, box: F64, d: CanopyDefinition, voxels: float | None = None
) -> dict[str, float]:
    """The traits of one plot from points ``xy`` (N, 2) at heights ``h`` (N,) above the
    ground, all inside the footprint ``box`` [xmin, ymin, xmax, ymax]; ``voxels``: the
    plot's occupied voxels as a survey's rays estimate them, in place of those holding
    a point (``services/traits/hidden.py``; None: those holding a point, as for the
    simulator's plants, whose every bit is known, or a survey without its scans'
    positions).
    Heights and volumes are NaN when the plot holds no canopy point, and cover too
    when it holds no point at all."""
    nx, ny = footprint_cells(box, d.cell)
    ix = np.clip(((xy[:, 0] - box[0]) / d.cell).astype(np.int64), 0, nx - 1)
    iy = np.clip(((xy[:, 1] - box[1]) / d.cell).astype(np.int64), 0, ny - 1)
    axis = row_axis(box)
    along, ns = (ix, nx) if axis == 0 else (iy, ny)
    lo_c, hi_c = box[1 - axis], box[3 - axis]
    width, length = hi_c - lo_c, box[2 + axis] - box[axis]
    seen = both_sides(along, xy[:, 1 - axis], lo_c, hi_c, ns)
    out = {"points": float(len(h)), "seen": float(seen.mean())}
    canopy = h >= d.min_height
    if not canopy.any():
        # nothing seen: cover unknown; seen, with no canopy: cover 0
        return {**out, "cover": 0.0 if len(h) else math.nan, **dict.fromkeys(_SHAPE, math.nan)}
    flat = (ix * ny + iy)[canopy]
    chm = np.full(nx * ny, -np.inf)
    np.maximum.at(chm, flat, h[canopy])
    tops = chm[np.isfinite(chm)]
    out["height"] = float(np.percentile(tops, d.height_percentile))
    out["height_p50"] = float(np.percentile(tops, 50.0))
    out["height_max"] = float(tops.max())
    out["cover"] = float(min(1.0, _hull_volume(xy[canopy], 2) / (width * length)))
    if voxels is None:
        # one int64 key per voxel: a 1-D unique is far faster than unique rows
        vz = np.floor(h[canopy] / d.voxel).astype(np.int64)
        vx = np.floor((xy[canopy, 0] - box[0]) / d.voxel).astype(np.int64)
        vy = np.floor((xy[canopy, 1] - box[1]) / d.voxel).astype(np.int64)
        span = 1 << 20  # voxels per axis (105 km at 10 cm); offsets keep keys non-negative
        keys = ((vx + span // 2) * span + (vy + span // 2)) * span + vz
        voxels = np.unique(keys).size
    out["volume_voxel"] = float(voxels * d.voxel**3)
    out["volume_hull"] = _hull_volume(np.column_stack([xy[canopy], h[canopy]]), 3)
    return out


_SHAPE = ("height", "height_p50", "height_max", "volume_voxel", "volume_hull")


def _hull_volume(pts: F64, dim: int) -> float:
    """Volume (area for ``dim`` 2) of the convex hull of ``pts`` (N, dim); 0 for too few
    points or a flat set, which has none."""
    from scipy.spatial import ConvexHull, QhullError

    if len(pts) < dim + 1:
        return 0.0
    try:
        return float(ConvexHull(pts).volume)
    except QhullError:
        return 0.0
