"""How far from its planned scan location may the robot stop before the plan sees less?

Measured with the planner's own visibility model: the cells a plan covers are the cells
its locations see (:func:`services.planner.visibility.compute_visibility`, thresholded
at ``min_hits`` as :func:`services.planner.core.plan` does), and a displaced stop is
just another origin for the same kernels, so the answer assumes nothing the planner
does not. Counts all cells (a plan given ``targets`` counts only those). Pure.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import msgspec
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp

# the planner's own clearance rule for candidates; turned into a footprint test below
from common.arrays import F64, I64
from common.field import Field, FieldLayout, ScannerModel, _clear
from common.messages.plan import PlanOptions
from services.planner.visibility import compute_visibility

RADII = (0.0, 0.02, 0.05, 0.10, 0.20, 0.30, 0.50)  # m
# eight compass directions, counter-clockwise from the field's +x axis (the rows)
DIRECTIONS = np.array([[np.cos(a), np.sin(a)] for a in np.radians(np.arange(0, 360, 45))])
STEP = 0.005  # m: how finely the path off the mark is checked for collisions


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """Per radius (m), shares of the plan's covered cells that stay covered: ``worst``
    and ``mean`` over the seeded draws (the worst of a sample: it moves with the seed);
    ``guaranteed``: kept whichever of the 8 directions each stop takes (a lower bound
    over all 8^M combinations, not sampled); ``shortened``: share of (location,
    direction) stops the robot's free space cut short."""

    radii: tuple[float, ...]
    worst: tuple[float, ...]
    mean: tuple[float, ...]
    guaranteed: tuple[float, ...]
    shortened: tuple[float, ...]
    covered: int  # cells the plan covers at its marks
    draws: int

    def first_below(self, share: float) -> float | None:
        """The smallest radius whose worst draw keeps less than ``share``; None if none."""
        return next((r for r, w in zip(self.radii, self.worst, strict=True) if w < share), None)


def free_run(layout: FieldLayout, field: Field, locations: F64, reach: float) -> F64:
    """(M, 8) how far (m, up to ``reach``) the robot can move from each location in each
    direction before its footprint would touch a plot or leave the field.

    The footprint test is the planner's candidate rule without its minimum scan distance
    (a stop nearer the plants than that is still a stop; the scanner's minimum range,
    which the visibility kernels apply, then hides what is too close). The centre keeps
    half the robot's width inside the boundary: beyond it is someone else's crop. The
    whole path from the mark is checked, as a robot drifting off its mark moves
    continuously and cannot pass through a plot to a free spot beyond it.
    """
    rule = msgspec.structs.replace(layout, min_scan_distance=0.0)
    ts = np.arange(0.0, reach + STEP, STEP)
    pts = locations[:, None, None, :] + ts[None, None, :, None] * DIRECTIONS[None, :, None, :]
    flat = pts.reshape(-1, 2)
    lo, hi = field.bounds[:2] + layout.robot_half_width, field.bounds[2:] - layout.robot_half_width
    ok = _clear(rule, flat, field.plot_boxes) & np.all((flat >= lo) & (flat <= hi), axis=1)
    ok = ok.reshape(pts.shape[:3])
    if not ok[:, :, 0].all():
        bad = locations[~ok[:, 0, 0]][0].tolist()
        raise ValueError(f"tolerance: location {bad} is not a free robot position")
    # the first blocked step ends the run; a run never blocked reaches ``reach``
    first_bad = np.where(ok.all(axis=2), len(ts), np.argmin(ok, axis=2))
    return np.minimum(ts[np.maximum(first_bad - 1, 0)], reach)


def tolerance(
    layout: FieldLayout,
    field: Field,
    locations: F64,
    scanner: ScannerModel | None = None,
    options: PlanOptions | None = None,
    *,
    radii: Sequence[float] = RADII,
    draws: int = 64,
    seed: int = 0,
) -> Tolerance:
    """Shares of the covered cells of the plan with ``locations`` (M, 2; field frame)
    that stay covered when every stop is ``r`` off its mark, for each ``r`` in
    ``radii``; ``options`` as the plan was made with (its visibility mode, samples,
    grid step and ``min_hits``).

    Each stop takes its own direction, drawn (seeded) from the 8 compass directions,
    the same draws at every radius so that the curve over ``r`` is not redrawn noise.
    Independent directions are the fair model of stopping off a mark: each stop is its
    own control event, ending short of or past the mark along the leg it arrived on and
    beside it across the lane, and the tour reaches each location along a different
    leg. Shifting every stop the same way models a localisation bias (a wrong antenna
    offset or georeference) instead: 8 of the 8^M combinations, which ``guaranteed``
    bounds too. A direction blocked by plants or the boundary ends the stop where it is
    blocked (:func:`free_run`).
    """
    opt = options or PlanOptions()
    scanner = scanner or ScannerModel()
    marks = np.asarray(locations, dtype=np.float64).reshape(-1, 2)
    m, rr = len(marks), np.asarray(radii, dtype=np.float64)
    if m == 0 or rr.size == 0 or np.any(rr < 0) or draws < 1:
        raise ValueError("tolerance: expected locations, radii >= 0 and draws >= 1")
    run = free_run(layout, field, marks, float(rr.max()))
    # row 0: the marks themselves, whose cover is the plan's as core.plan counts it
    dist = np.minimum(np.concatenate([[0.0], rr])[:, None, None], run[None])  # (1 + R, M, 8)
    stops = marks[None, :, None, :] + dist[..., None] * DIRECTIONS[None, None, :, :]
    # one visibility origin per distinct stop: blocked directions end at the same point
    uniq, inv = np.unique(np.round(stops.reshape(-1, 2), 9), axis=0, return_inverse=True)
    row = inv.reshape(stops.shape[:3])
    probe = dataclasses.replace(
        field,
        cand_xy=uniq,
        cand_ids=np.arange(1, len(uniq) + 1, dtype=np.int64),
        cand_row_lane=np.full(len(uniq), -1, dtype=np.int64),
        cand_cross_lane=np.full(len(uniq), -1, dtype=np.int64),
    )
    vis = compute_visibility(
        probe, scanner, opt.visibility, samples=opt.samples, step_deg=opt.grid_step_deg
    )
    seen = vis.matrix(opt.min_hits).astype(np.int64)

    def cells(rows: I64) -> npt.NDArray[np.bool_]:
        return np.asarray(seen[rows].sum(axis=0)).ravel() > 0

    base = cells(row[0, :, 0])
    covered = int(base.sum())
    if covered == 0:
        raise ValueError("tolerance: the locations see no cell")
    pick = np.random.default_rng(seed).integers(0, 8, size=(draws, m))
    # sums each location's 8 direction rows: a cell seen from all 8 keeps its count 8
    ones = np.ones(8 * m, dtype=np.int64)
    per_loc = sp.csr_matrix((ones, (np.repeat(np.arange(m), 8), np.arange(8 * m))))
    worst, mean, sure, short = [], [], [], []
    for i, r in enumerate(rr, start=1):
        kept = [int((cells(row[i, np.arange(m), d]) & base).sum()) / covered for d in pick]
        all8 = (per_loc @ seen[row[i].ravel()]).tocsr()
        all8.data = (all8.data == 8).astype(np.int64)
        sure.append(int(((np.asarray(all8.sum(axis=0)).ravel() > 0) & base).sum()) / covered)
        worst.append(min(kept))
        mean.append(float(np.mean(kept)))
        short.append(float(np.mean(run < r)))
    return Tolerance(
        radii=tuple(float(r) for r in rr),
        worst=tuple(worst),
        mean=tuple(mean),
        guaranteed=tuple(sure),
        shortened=tuple(short),
        covered=covered,
        draws=draws,
    )
