"""The paper's navigation experiments (section 6.1) as routes and statistics. Pure.

- border: the field's outer lanes, corner to corner clockwise from the Origin, with
  in-place 90 deg turns (paper Figure 19);
- serpentine: up and down every cross lane (alleys and headlands), joined along the
  outer row lanes, out and back, twice (Figure 20);
- stationary: hold a scan location for a scan's duration (Figures 21-22).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from common.arrays import F64
from common.field import Field
from common.geo import wrap_angle
from common.messages.nav import Leg


def legs_through(points: Sequence[tuple[float, float]]) -> list[Leg]:
    """Straight legs through ``points``, each ending with an in-place turn to the
    next leg's heading."""
    legs = []
    for i in range(len(points) - 1):
        (x0, y0), (x1, y1) = points[i], points[i + 1]
        nxt = None
        if i + 2 < len(points):
            (nx, ny) = points[i + 2]
            nxt = math.atan2(ny - y1, nx - x1)
        legs.append(Leg(x0=x0, y0=y0, x1=x1, y1=y1, final_yaw=nxt))
    return legs


def border_points(f: Field) -> list[tuple[float, float]]:
    xs, ys = f.cross_lanes_x, f.row_lanes_y
    x0, x1 = round(float(xs[0]), 9), round(float(xs[-1]), 9)
    y0, y1 = round(float(ys[0]), 9), round(float(ys[-1]), 9)
    ox, oy = float(f.origin_xy[0]), float(f.origin_xy[1])
    corners = [(x1, y0), (x0, y0), (x0, y1), (x1, y1)]  # clockwise from bottom-right
    k = min(range(4), key=lambda i: math.hypot(corners[i][0] - ox, corners[i][1] - oy))
    ring = corners[k:] + corners[:k]
    return [*ring, ring[0]]


def serpentine_points(f: Field, passes: int = 2) -> list[tuple[float, float]]:
    xs = [round(float(x), 9) for x in f.cross_lanes_x]
    y0, y1 = round(float(f.row_lanes_y[0]), 9), round(float(f.row_lanes_y[-1]), 9)
    if abs(float(f.origin_xy[0]) - xs[-1]) < abs(float(f.origin_xy[0]) - xs[0]):
        xs = xs[::-1]  # start on the Origin's side
    y = y0
    pts: list[tuple[float, float]] = [(xs[0], y)]
    for p in range(2 * passes):  # out and back, ``passes`` times
        for i, x in enumerate(xs if p % 2 == 0 else xs[::-1]):
            if i > 0:
                pts.append((x, y))  # along the outer row lane to the next cross lane
            y = y1 if y == y0 else y0
            pts.append((x, y))  # up or down the cross lane
    return pts


def track_errors(
    xy: F64, yaw: F64, leg_idx: npt.NDArray[np.int64], legs: Sequence[Leg]
) -> tuple[F64, F64]:
    """Signed cross-track (m, left positive) and heading errors (rad) of poses
    against the leg each was following."""
    xte = np.empty(len(xy))
    herr = np.empty(len(xy))
    for i, (p, th, k) in enumerate(zip(xy, yaw, leg_idx, strict=True)):
        lg = legs[int(k)]
        dx, dy = lg.x1 - lg.x0, lg.y1 - lg.y0
        n = math.hypot(dx, dy) or 1.0
        xte[i] = (-(p[0] - lg.x0) * dy + (p[1] - lg.y0) * dx) / n
        herr[i] = wrap_angle(float(th) - math.atan2(dy, dx))
    return xte, herr


def track_stats(xte: F64, herr: F64) -> dict[str, float]:
    """The paper's statistics: mean and SD of |cross-track error|, shares of the path
    below 5 cm, 5-10 cm and above 10 cm; heading error mean and SD (degrees); and
    the 99th percentile of |cross-track error|."""
    a = np.abs(xte)
    h = np.degrees(herr)
    return {
        "samples": float(len(a)),
        "xte_mean_cm": float(100 * a.mean()),
        "xte_sd_cm": float(100 * a.std()),
        "xte_max_cm": float(100 * a.max()),
        # the lanes leave the Husky about 6 cm each side: the tail matters as the mean
        "xte_p99_cm": float(100 * np.percentile(a, 99)),
        "share_below_5cm": float(np.mean(a < 0.05)),
        "share_5_10cm": float(np.mean((a >= 0.05) & (a <= 0.10))),
        "share_above_10cm": float(np.mean(a > 0.10)),
        "heading_mean_deg": float(h.mean()),
        "heading_sd_deg": float(h.std()),
    }


def path_length(xy: F64) -> float:
    """Length (m) of the polyline through the (N, 2) points ``xy``; 0 for fewer than 2."""
    if len(xy) < 2:
        return 0.0
    return float(np.hypot(*np.diff(xy, axis=0).T).sum())


def stationary_stats(xy: F64, yaw: F64, goal: tuple[float, float, float]) -> dict[str, float]:
    """Residuals of poses held at a scan location against their mean and against the
    planned point ``goal`` (x, y, yaw)."""
    d = np.hypot(xy[:, 0] - goal[0], xy[:, 1] - goal[1])
    res = xy - xy.mean(axis=0)
    herr = np.degrees([wrap_angle(float(t) - goal[2]) for t in yaw])
    # residuals about the held heading, as the paper's Figures 21-22 plot them
    hres = herr - herr.mean()
    return {
        "samples": float(len(xy)),
        "distance_to_planned_mean_cm": float(100 * d.mean()),
        "distance_to_planned_sd_cm": float(100 * d.std()),
        "residual_x_sd_cm": float(100 * res[:, 0].std()),
        "residual_y_sd_cm": float(100 * res[:, 1].std()),
        "heading_error_mean_abs_deg": float(np.abs(herr).mean()),
        "heading_error_mean_deg": float(herr.mean()),
        "heading_residual_mean_abs_deg": float(np.abs(hres).mean()),
        "heading_residual_sd_deg": float(np.std(herr)),
    }
