"""The lidar stop: is anything in the box ahead of the robot? Pure."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]


def _in_base_link(
    ranges: npt.NDArray[np.floating],
    angle_min: float,
    angle_increment: float,
    lidar: tuple[float, float, float],
) -> tuple[F64, F64]:
    """x and y (m) in base_link of every return (inf ranges dropped)."""
    r = np.asarray(ranges, dtype=np.float64)
    a = lidar[2] + angle_min + angle_increment * np.arange(len(r))
    ok = np.isfinite(r)
    return lidar[0] + r[ok] * np.cos(a[ok]), lidar[1] + r[ok] * np.sin(a[ok])


def obstacle_ahead(
    ranges: npt.NDArray[np.floating],
    angle_min: float,
    angle_increment: float,
    lidar: tuple[float, float, float],
    front_x: float,
    distance: float,
    half_width: float,
    min_points: int = 3,
) -> bool:
    """True if a return lies within ``distance`` ahead of the robot's front (base_link
    x = ``front_x``) and ``half_width`` of its centre line. Ranges in metres, inf for
    no return; the lidar sits at ``lidar`` = (x, y, yaw) in base_link (m, rad), its
    0-degree beam along yaw. ``min_points`` returns are needed, so a single noisy
    return (the UST-05LX's +-40 mm) off a plot edge beside a narrow lane does not stop
    the robot."""
    x, y = _in_base_link(ranges, angle_min, angle_increment, lidar)
    inside = (x > front_x) & (x < front_x + distance) & (np.abs(y) < half_width)
    return int(np.count_nonzero(inside)) >= min_points


def obstacle_on_leg(
    ranges: npt.NDArray[np.floating],
    angle_min: float,
    angle_increment: float,
    lidar: tuple[float, float, float],
    pose: tuple[float, float, float],
    leg: tuple[float, float, float, float],
    front_x: float,
    distance: float,
    half_width: float,
    min_points: int = 3,
) -> bool:
    """Like :func:`obstacle_ahead`, but the box is aligned with the leg being followed
    (x0, y0, x1, y1 in the field frame) rather than with the robot's body: after an
    in-place turn the robot may sit 2 deg and a few cm off its lane, and a body-aligned
    box then reaches the plot edges 0.4 m beside a narrow lane. ``pose`` is the
    robot's (x, y, yaw) in the field frame."""
    bx, by = _in_base_link(ranges, angle_min, angle_increment, lidar)
    x, y, yaw = pose
    c, s = np.cos(yaw), np.sin(yaw)
    px, py = x + c * bx - s * by, y + s * bx + c * by
    x0, y0, x1, y1 = leg
    n = float(np.hypot(x1 - x0, y1 - y0))
    if n < 1e-6:
        return False
    ux, uy = (x1 - x0) / n, (y1 - y0) / n
    along = (px - x0) * ux + (py - y0) * uy
    cross = -(px - x0) * uy + (py - y0) * ux
    robot_along = (x - x0) * ux + (y - y0) * uy
    ahead = (along > robot_along + front_x) & (along < robot_along + front_x + distance)
    return int(np.count_nonzero(ahead & (np.abs(cross) < half_width))) >= min_points
