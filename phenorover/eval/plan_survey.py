"""Scoring a plan on the simulator's true foliage: of the planner's cells that truly hold
foliage, how many does at least one scan from the plan's locations hit?

The cells are the nominal ones the planner cuts (``voxel_x`` x ``voxel_y`` x ``voxel_z``
of each plot box, heights counted from the ground under them), continued past the box
into the lanes where a trial's plants lean out of it; a cell counts when it holds any
true foliage voxel (:mod:`services.sim.foliage`). A scan is rendered with the robot
settled at each location (yaw 0), as the survey would take it, and each foliage return
is put into the voxel it hit, so seen cells are always a subset of the true ones.

This reads simulation truth, so it lives here in the evaluation, never in a service.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from common.arrays import F64, I64
from common.messages.plan import PlanResult
from services.sim.foliage import EMPTY
from services.sim.render import ScanSettings
from services.sim.robot import RobotState
from services.sim.scene import LEAF_HIT, STEM_HIT
from services.sim.world import World

DEFAULT_STEP_DEG = 0.5
# cells reach at most this many past a plot box's side (lean margins are <= 1 m)
_PAD = 16


class _Cells:
    """The field's nominal cell grid, extended by :data:`_PAD` cells on every side, as
    int64 keys ``((p * W + ix) * H + iy) * Z + iz``."""

    def __init__(self, world: World) -> None:
        fld = world.field
        self.boxes = fld.plot_boxes
        self.dims = fld.cell_dims
        self.size = (self.boxes[:, 3:6] - self.boxes[:, 0:3]) / self.dims
        self.w = int(self.dims[:, 0].max()) + 2 * _PAD
        self.h = int(self.dims[:, 1].max()) + 2 * _PAD
        self.z = int(self.dims[:, 2].max())
        self.terrain = world.terrain

    def keys(self, p: I64, pts: F64) -> I64:
        """Cell keys of points ``pts`` (N, 3, field frame) of plots ``p`` (N,)."""
        b, s, n = self.boxes[p], self.size[p], self.dims[p]
        ground = self.terrain.height(pts[:, 0], pts[:, 1])
        ix = np.floor((pts[:, 0] - b[:, 0]) / s[:, 0]).astype(np.int64)
        iy = np.floor((pts[:, 1] - b[:, 1]) / s[:, 1]).astype(np.int64)
        # foliage a rounding above the box top (or below its base) is its top (base) cell
        iz = np.clip(np.floor((pts[:, 2] - ground - b[:, 2]) / s[:, 2]), 0, n[:, 2] - 1)
        ix = np.clip(ix + _PAD, 0, self.w - 1)
        iy = np.clip(iy + _PAD, 0, self.h - 1)
        return ((p * self.w + ix) * self.h + iy) * self.z + iz.astype(np.int64)


def true_cells(world: World) -> I64:
    """Sorted keys of the cells holding true foliage."""
    cells = _Cells(world)
    fol = world.foliage
    out = []
    for p in range(fol.n_plots):
        idx = np.argwhere(fol.grid(p) != EMPTY)
        centres = fol.origin[p] + (idx + 0.5) * fol.voxel
        out.append(np.unique(cells.keys(np.full(len(idx), p, dtype=np.int64), centres)))
    return np.unique(np.concatenate(out)) if out else np.zeros(0, dtype=np.int64)


def _hit_voxels(world: World, pts: F64, origin: F64) -> tuple[I64, F64]:
    """The plot and the centre of the occupied foliage voxel each foliage return
    ``pts`` (N, 3, field frame) hit; returns that do not land in one are dropped."""
    fol = world.foliage
    d = pts - origin
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    plot = np.full(len(pts), -1, dtype=np.int64)
    centre = np.zeros_like(pts)
    # a return sits on the face the ray entered its voxel by: a quarter voxel further
    # along the ray is inside it (the point itself when that misses, e.g. grazing)
    for q in (pts + d * fol.voxel / 4, pts):
        for p in range(fol.n_plots):
            todo = plot < 0
            v = np.floor((q[todo] - fol.origin[p]) / fol.voxel).astype(np.int64)
            n = fol.dims[p]
            inside = np.all((v >= 0) & (v < n), axis=1)
            if not inside.any():
                continue
            vi = v[inside]
            occupied = fol.grid(p)[vi[:, 0], vi[:, 1], vi[:, 2]] != EMPTY
            rows = np.flatnonzero(todo)[np.flatnonzero(inside)[occupied]]
            plot[rows] = p
            centre[rows] = fol.origin[p] + (vi[occupied] + 0.5) * fol.voxel
    ok = plot >= 0
    return plot[ok], centre[ok]


def seen_by_location(
    world: World, locations_xy: F64, settings: ScanSettings | None = None, seed: int = 0
) -> list[I64]:
    """Per location (M, 2), the sorted keys of the cells its scan's foliage returns hit."""
    settings = settings or ScanSettings(step_deg=DEFAULT_STEP_DEG)
    cells = _Cells(world)
    out = []
    for k, (x, y) in enumerate(np.asarray(locations_xy, dtype=np.float64).reshape(-1, 2)):
        rng = np.random.default_rng([seed, k])
        state = world.settle(RobotState(x=float(x), y=float(y), yaw=0.0))
        pose = world.scanner_pose(state)
        scan = world.render_scan(pose, settings, rng)
        foliage = np.isin(scan.label, (LEAF_HIT, STEM_HIT))
        pts = scan.points[foliage] @ pose[:3, :3].T + pose[:3, 3]
        plot, centre = _hit_voxels(world, pts, pose[:3, 3])
        out.append(np.unique(cells.keys(plot, centre)))
    return out


def truly_seen_cells(
    world: World, locations_xy: F64, settings: ScanSettings | None = None, seed: int = 0
) -> tuple[int, int]:
    """(cells holding true foliage that a scan from some location hit, cells holding
    true foliage)."""
    truth = true_cells(world)
    seen = _union(seen_by_location(world, locations_xy, settings, seed))
    return int(np.isin(seen, truth).sum()), int(truth.size)


def _union(sets: Iterable[I64]) -> I64:
    parts = list(sets)
    return np.unique(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)


def locations(result: PlanResult) -> F64:
    """(M, 2) field-frame positions of a plan's selected locations."""
    at = {c.id: (c.x, c.y) for c in result.candidates}
    return np.array([at[i] for i in result.selected], dtype=np.float64).reshape(-1, 2)


def compare_plans(
    world: World,
    nominal_xy: F64,
    measured_xy: F64,
    settings: ScanSettings | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Truly seen cells of two plans on one world; a location both plans share is
    rendered once. ``{"cells_total": T, "nominal": {...}, "measured": {...}}`` with
    per plan ``locations``, ``cells_seen`` and ``share`` (seen / total)."""
    a = np.asarray(nominal_xy, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(measured_xy, dtype=np.float64).reshape(-1, 2)
    # one scan per distinct location (positions rounded to the millimetre)
    both, inverse = np.unique(np.round(np.vstack([a, b]), 3), axis=0, return_inverse=True)
    per = seen_by_location(world, both.astype(np.float64), settings, seed)
    truth = true_cells(world)
    out: dict[str, Any] = {"cells_total": int(truth.size)}
    inverse = inverse.ravel()  # numpy 2.0-2.1 keep the input's shape here
    for name, rows in (("nominal", inverse[: len(a)]), ("measured", inverse[len(a) :])):
        seen = int(np.isin(_union(per[int(r)] for r in rows), truth).sum())
        out[name] = {
            "locations": len(rows),
            "cells_seen": seen,
            "share": seen / truth.size if truth.size else 0.0,
        }
    return out
