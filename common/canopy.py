"""What a plot's canopy traits are: one definition, applied to the points a survey
measured (``services/traits``) and to the simulator's plants (``services/sim``), so a
trait and its truth differ only by what the scanner saw.

Every trait is computed from points given as field-frame x, y and height above the
ground h (metres), cut to one plot's footprint ``[xmin, ymin, xmax, ymax]``. The
footprint is cut into square cells of ``cell`` metres (aligned with its lower-left
corner); a point with ``h >= min_height`` is canopy, lower ones are ground.

- the *canopy height model* (CHM): in every cell holding canopy, the highest canopy
  point's h (the usual LiDAR CHM, e.g. Jimenez-Berni et al. 2018, Front. Plant Sci.
  9:237);
- ``height``: the ``height_percentile`` (95th) of the CHM over canopy cells, with
  ``height_p50`` and ``height_max`` beside it;
- ``cover``: canopy cells over all cells of the footprint (projected cover, 0-1);
- ``volume_columns``: the volume under the CHM (sum of cell area x CHM height; the
  "canopy volume" of Sun et al. 2018);
- ``volume_voxel``: occupied ``voxel``-metre cubes of canopy (heights counted from the
  ground, so voxels follow the terrain) times the voxel volume;
- ``volume_hull``: the convex hull of the canopy points (x, y, h);
- ``points``: points in the footprint; ``seen``: cells holding any point (ground or
  canopy) over all cells, the share of the plot's surface the survey saw.
"""

from __future__ import annotations

import math
from typing import Annotated

import msgspec
import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

# trait name -> unit, in the order the field book's columns list them
TRAITS: dict[str, str] = {
    "height": "m",
    "height_p50": "m",
    "height_max": "m",
    "cover": "1",
    "volume_columns": "m3",
    "volume_voxel": "m3",
    "volume_hull": "m3",
    "points": "1",
    "seen": "1",
}
Cell = Annotated[float, msgspec.Meta(ge=0.005, le=1.0)]


class CanopyDefinition(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The definitions' parameters (metres; a percentile in 0-100)."""

    cell: Cell = 0.05
    voxel: Cell = 0.05
    min_height: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.05
    height_percentile: Annotated[float, msgspec.Meta(ge=50.0, le=100.0)] = 95.0

    def method(self, trait: str) -> str:
        """How ``trait`` is computed, in words (the long-format CSV's ``method``)."""
        c, v, m = self.cell * 100, self.voxel * 100, self.min_height * 100
        return {
            "height": f"p{self.height_percentile:g} of the canopy height model "
            f"({c:g} cm cells, canopy >= {m:g} cm above ground)",
            "height_p50": f"p50 of the canopy height model ({c:g} cm cells)",
            "height_max": f"max of the canopy height model ({c:g} cm cells)",
            "cover": f"canopy cells / footprint cells ({c:g} cm cells, canopy >= {m:g} cm)",
            "volume_columns": f"volume under the canopy height model ({c:g} cm cells)",
            "volume_voxel": f"occupied {v:g} cm voxels of canopy, terrain-following",
            "volume_hull": "convex hull of the canopy points",
            "points": "points inside the plot footprint",
            "seen": f"footprint cells holding any point ({c:g} cm cells)",
        }[trait]


def footprint_cells(box: F64, cell: float) -> tuple[int, int]:
    """Cells (nx, ny) of a footprint ``[xmin, ymin, xmax, ymax]``."""
    return (
        max(1, math.ceil((box[2] - box[0]) / cell - 1e-9)),
        max(1, math.ceil((box[3] - box[1]) / cell - 1e-9)),
    )


def plot_traits(xy: F64, h: F64, box: F64, d: CanopyDefinition) -> dict[str, float]:
    """The traits of one plot from points ``xy`` (N, 2) at heights ``h`` (N,) above the
    ground, all inside the footprint ``box`` [xmin, ymin, xmax, ymax]. Heights and
    volumes are NaN when the plot holds no canopy point."""
    nx, ny = footprint_cells(box, d.cell)
    ix = np.clip(((xy[:, 0] - box[0]) / d.cell).astype(np.int64), 0, nx - 1)
    iy = np.clip(((xy[:, 1] - box[1]) / d.cell).astype(np.int64), 0, ny - 1)
    flat = ix * ny + iy
    seen = np.unique(flat).size / (nx * ny) if len(flat) else 0.0
    canopy = h >= d.min_height
    out = {"points": float(len(h)), "seen": float(seen)}
    nan = float("nan")
    if not canopy.any():
        return {**out, "cover": 0.0, **dict.fromkeys(_SHAPE, nan)}
    chm = np.full(nx * ny, -np.inf)
    np.maximum.at(chm, flat[canopy], h[canopy])
    tops = chm[np.isfinite(chm)]
    out["cover"] = float(tops.size / (nx * ny))
    out["height"] = float(np.percentile(tops, d.height_percentile))
    out["height_p50"] = float(np.percentile(tops, 50.0))
    out["height_max"] = float(tops.max())
    out["volume_columns"] = float(tops.sum() * d.cell**2)
    # one int64 key per voxel: a 1-D unique is far faster than unique rows
    vz = np.floor(h[canopy] / d.voxel).astype(np.int64)
    vx = np.floor((xy[canopy, 0] - box[0]) / d.voxel).astype(np.int64)
    vy = np.floor((xy[canopy, 1] - box[1]) / d.voxel).astype(np.int64)
    span = 1 << 20  # voxels per axis: 52 km at 5 cm, offsets keep keys non-negative
    keys = ((vx + span // 2) * span + (vy + span // 2)) * span + vz
    out["volume_voxel"] = float(np.unique(keys).size * d.voxel**3)
    out["volume_hull"] = _hull_volume(np.column_stack([xy[canopy], h[canopy]]))
    return out


_SHAPE = ("height", "height_p50", "height_max", "volume_columns", "volume_voxel", "volume_hull")


def _hull_volume(pts: F64) -> float:
    """Volume of the convex hull of ``pts`` (N, 3); 0 for fewer than four points or a
    flat set, which has no volume."""
    from scipy.spatial import ConvexHull, QhullError

    if len(pts) < 4:
        return 0.0
    try:
        return float(ConvexHull(pts).volume)
    except QhullError:
        return 0.0
