"""Localization and route following."""

from __future__ import annotations

import enum
from typing import Annotated

import msgspec

from common.messages.core import Message, NonNegative


class PoseEstimate(Message, frozen=True, kw_only=True):
    """The EKF's estimate of base_link in the ``field`` frame.

    ``covariance`` is row-major 3x3 over (x, y, yaw) in m^2, m*rad, rad^2. ``localized``
    turns false when the position uncertainty passes the configured bound; navigation
    stops while it is false.
    """

    x: float
    y: float
    yaw: float
    z: float = 0.0
    v: float = 0.0
    w: float = 0.0
    covariance: tuple[float, ...] = (0.0,) * 9
    localized: bool = False


class Leg(msgspec.Struct, frozen=True, kw_only=True):
    """A straight leg in the ``field`` frame from (x0, y0) to (x1, y1), metres.

    ``final_yaw`` is the heading to rotate to in place on arrival (the next leg's
    direction); ``None`` keeps the arrival heading. ``scan_id`` marks a leg that ends
    at a scan location.
    """

    x0: float
    y0: float
    x1: float
    y1: float
    final_yaw: float | None = None
    scan_id: int | None = None


class FollowRoute(msgspec.Struct, frozen=True, tag=True):
    route_id: str
    legs: list[Leg]
    max_speed: Annotated[float, msgspec.Meta(gt=0, le=2.0)] = 0.5


class CancelRoute(msgspec.Struct, frozen=True, tag=True):
    route_id: str = ""


NavCommand = FollowRoute | CancelRoute


class NavReply(Message, frozen=True, kw_only=True):
    accepted: bool
    reason: str = ""


class NavState(enum.StrEnum):
    IDLE = "idle"
    DRIVING = "driving"
    ROTATING = "rotating"
    POSITIONING = "positioning"  # fine positioning at the route's end (a scan location)
    ARRIVED = "arrived"
    BLOCKED = "blocked"
    WAITING_OBSTACLE = "waiting_obstacle"
    NOT_LOCALIZED = "not_localized"
    CANCELLED = "cancelled"


class NavProgress(Message, frozen=True, kw_only=True):
    """Route-following progress in the ``field`` frame (metres, radians)."""

    route_id: str
    state: NavState
    leg: int = 0
    legs: int = 0
    distance_to_go: NonNegative = 0.0
    cross_track: float = 0.0
    heading_error: float = 0.0
