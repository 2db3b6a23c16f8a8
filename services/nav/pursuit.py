"""Pure pursuit on a straight leg (paper section 4.3.2, Coulter 1992). Pure."""

from __future__ import annotations

import math

from common.geo import wrap_angle
from common.messages.nav import Leg


def lookahead_point(
    x: float,
    y: float,
    x0: float,
    y0: float,
    x1: float,
    y1: float,
    lookahead: float,
    beyond: bool = False,
) -> tuple[float, float]:
    """The point of segment (x0,y0)->(x1,y1) at distance ``lookahead`` from the robot,
    ahead of its projection; the segment end when that lies closer than ``lookahead``
    (so the robot homes in on the goal) unless ``beyond``, which lets the point run on
    along the segment's line; the projection moved ahead along the segment when the
    robot is farther than ``lookahead`` from the line."""
    dx, dy = x1 - x0, y1 - y0
    seg = math.hypot(dx, dy)
    if seg < 1e-9:
        return x1, y1
    ux, uy = dx / seg, dy / seg
    along = (x - x0) * ux + (y - y0) * uy
    cross = -(x - x0) * uy + (y - y0) * ux
    if abs(cross) >= lookahead:
        ahead = along
    else:
        ahead = along + math.sqrt(lookahead * lookahead - cross * cross)
    ahead = min(max(ahead, 0.0), seg + (lookahead if beyond else 0.0))
    return x0 + ahead * ux, y0 + ahead * uy


def curvature(x: float, y: float, yaw: float, px: float, py: float) -> float:
    """Curvature 2 sin(alpha) / L_D of the arc from the robot pose to (px, py) (paper
    eq. 4), alpha the bearing of the point in the robot frame, L_D its distance."""
    ld = math.hypot(px - x, py - y)
    if ld < 1e-9:
        return 0.0
    alpha = wrap_angle(math.atan2(py - y, px - x) - yaw)
    return 2.0 * math.sin(alpha) / ld


def cross_track(x: float, y: float, x0: float, y0: float, x1: float, y1: float) -> float:
    """Signed distance (left positive) of (x, y) from the line through the segment."""
    dx, dy = x1 - x0, y1 - y0
    seg = math.hypot(dx, dy)
    if seg < 1e-9:
        return math.hypot(x - x1, y - y1)
    return (-(x - x0) * dy + (y - y0) * dx) / seg


def along_remaining(x: float, y: float, x0: float, y0: float, x1: float, y1: float) -> float:
    """Distance still to go to the segment end, measured along the segment."""
    dx, dy = x1 - x0, y1 - y0
    seg = math.hypot(dx, dy)
    if seg < 1e-9:
        return 0.0
    return ((x1 - x) * dx + (y1 - y) * dy) / seg


def segment_distance(x: float, y: float, x0: float, y0: float, x1: float, y1: float) -> float:
    """Distance from (x, y) to the closed segment (x0,y0)-(x1,y1)."""
    dx, dy = x1 - x0, y1 - y0
    seg2 = dx * dx + dy * dy
    u = 0.0 if seg2 < 1e-18 else max(0.0, min(1.0, ((x - x0) * dx + (y - y0) * dy) / seg2))
    return math.hypot(x - (x0 + u * dx), y - (y0 + u * dy))


def predict(
    x: float, y: float, yaw: float, v: float, w: float, t: float
) -> tuple[float, float, float]:
    """The pose ``t`` seconds ahead driving at (v, w): what a command sent now acts on
    once the drivetrain has taken it in."""
    mid = yaw + 0.5 * w * t
    return x + v * t * math.cos(mid), y + v * t * math.sin(mid), yaw + w * t


def ramp(target: float, current: float, rate: float, dt: float) -> float:
    """``current`` moved toward ``target`` by at most ``rate`` per second over ``dt``:
    a command within the drivetrain's acceleration."""
    return current + max(-rate * dt, min(rate * dt, target - current))


def aim_at(x: float, y: float, leg: Leg, lookahead: float) -> float:
    """The heading to turn to before driving ``leg``: toward its look-ahead point, so
    a robot that a corner's turn in place shifted sideways heads back to the line from
    the start instead of over the first metres; the leg's own near its end."""
    px, py = lookahead_point(x, y, leg.x0, leg.y0, leg.x1, leg.y1, lookahead)
    if math.hypot(px - x, py - y) < lookahead / 2:
        return math.atan2(leg.y1 - leg.y0, leg.x1 - leg.x0)
    return math.atan2(py - y, px - x)
