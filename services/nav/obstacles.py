"""The lidar stop: which returns lie in the box ahead of the robot? Pure.

Both functions return the returns inside the box, not a verdict: the service stops
on ``obstacle_min_points`` of them (a single noisy return, the UST-05LX's +-40 mm,
off a plot edge beside a narrow lane must not stop the robot) and says where they
are, so a robot that waits in a lane can be told from one that waits for nothing.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from common.arrays import F64


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


def hits_ahead(
    ranges: npt.NDArray[np.floating],
    angle_min: float,
    angle_increment: float,
    lidar: tuple[float, float, float],
    front_x: float,
    distance: float,
    half_width: float,
) -> F64:
    """The returns (k, 2: base_link x, y in m) within ``distance`` ahead of the
    robot's front (base_link x = ``front_x``) and ``half_width`` of its centre line.
    Ranges in metres, inf for no return; the lidar sits at ``lidar`` = (x, y, yaw) in
    base_link (m, rad), its 0-degree beam along yaw."""
    x, y = _in_base_link(ranges, angle_min, angle_increment, lidar)
    inside = (x > front_x) & (x < front_x + distance) & (np.abs(y) < half_width)
    return np.column_stack([x[inside], y[inside]])


def hits_on_leg(
    ranges: npt.NDArray[np.floating],
    angle_min: float,
    angle_increment: float,
    lidar: tuple[float, float, float],
    pose: tuple[float, float, float],
    leg: tuple[float, float, float, float],
    front_x: float,
    distance: float,
    half_width: float,
    crop: F64 | None = None,
) -> F64:
    """Like :func:`hits_ahead`, but the box is aligned with the leg being followed
    (x0, y0, x1, y1 in the field frame) rather than with the robot's body, and the
    returns come in the field frame: after an in-place turn the robot may sit 2 deg
    and a few cm off its lane, and a body-aligned box then reaches the plot edges
    0.4 m beside a narrow lane. The box ends where the robot's front will be at the
    leg's end: what lies beyond is not on this leg (the next one begins with a turn
    in place). ``pose`` is the robot's (x, y, yaw) in the field frame. Returns inside
    one of the ``crop`` boxes (k, 4: x_min, y_min, x_max, y_max in the field frame,
    grown by the caller's margin) are the crop, not an obstacle: plants at a lane's
    edge never move out of the way, and a robot a few centimetres off its lane brushes
    them (the Husky is 0.67 m wide in a 0.8 m gap)."""
    bx, by = _in_base_link(ranges, angle_min, angle_increment, lidar)
    x, y, yaw = pose
    c, s = np.cos(yaw), np.sin(yaw)
    px, py = x + c * bx - s * by, y + s * bx + c * by
    x0, y0, x1, y1 = leg
    n = float(np.hypot(x1 - x0, y1 - y0))
    if n < 1e-6:
        return np.empty((0, 2))
    ux, uy = (x1 - x0) / n, (y1 - y0) / n
    along = (px - x0) * ux + (py - y0) * uy
    cross = -(px - x0) * uy + (py - y0) * ux
    start = (x - x0) * ux + (y - y0) * uy + front_x
    end = min(start + distance, n + front_x)
    inside = (along > start) & (along < end) & (np.abs(cross) < half_width)
    px, py = px[inside], py[inside]
    if crop is not None and len(crop) and len(px):
        in_crop = (
            (px[:, None] >= crop[None, :, 0])
            & (py[:, None] >= crop[None, :, 1])
            & (px[:, None] <= crop[None, :, 2])
            & (py[:, None] <= crop[None, :, 3])
        ).any(axis=1)
        px, py = px[~in_crop], py[~in_crop]
    return np.column_stack([px, py])


class ObstacleWatch:
    """Whether the robot is held by an obstacle: ``min_points`` returns in the box
    in ``scans`` consecutive lidar scans (one scan's spray of returns from a leaf in
    the wind, or dust, does not stop the robot), and free again after as many scans
    without. What changed is said at most once per ``quiet_s`` (s): an obstacle at the
    box's edge may come and go for minutes, and the log must stay readable."""

    def __init__(self, min_points: int, scans: int, quiet_s: float = 10.0) -> None:
        self.min_points, self.scans, self.quiet_s = min_points, scans, quiet_s
        self.held = False
        self._run = 0  # consecutive scans that disagree with ``held``
        self._said_at = -math.inf  # when the robot's being held was last said
        self._said = False  # the last hold was said: its end is said too

    def update(self, t: float, hits: F64, frame: str) -> str | None:
        """Take one scan's ``hits`` (k, 2; m, in ``frame``) at ``t`` (s): what changed,
        in words (the returns' extent when the robot becomes held), or None."""
        seen = len(hits) >= self.min_points
        self._run = 0 if seen == self.held else self._run + 1
        if self._run < self.scans:
            return None
        self.held, self._run = seen, 0
        if not seen:
            said, self._said = self._said, False
            return "obstacle: the box ahead is clear" if said else None
        if t - self._said_at < self.quiet_s:
            return None
        self._said_at, self._said = t, True
        lo, hi = hits.min(axis=0), hits.max(axis=0)
        return (
            f"obstacle: {len(hits)} lidar returns in the box ahead, x {lo[0]:.2f}..{hi[0]:.2f}"
            f", y {lo[1]:.2f}..{hi[1]:.2f} ({frame}, m)"
        )
