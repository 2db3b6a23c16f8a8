"""Localization and route following."""

from __future__ import annotations

import enum
import math
from typing import Annotated

import msgspec

from common.messages.core import (
    Angle,
    Coordinate,
    Finite,
    Message,
    NonNegative,
    Velocity,
)


class PoseEstimate(Message, frozen=True, kw_only=True):
    """The EKF's estimate of base_link in the ``field`` frame.

    ``covariance`` is row-major 3x3 over (x, y, yaw) in m^2, m*rad, rad^2. ``localized``
    turns false when the position uncertainty passes the configured bound; navigation
    stops while it is false. ``tilted``: the antennas' lever arms were turned by
    base_link's ``roll`` and ``pitch`` (rad, from the IMU); false: a planar estimate
    (no IMU), which puts base_link where the antennas lean.
    """

    x: Coordinate
    y: Coordinate
    yaw: Angle
    z: Coordinate = 0.0
    v: Velocity = 0.0
    w: Velocity = 0.0
    covariance: tuple[Finite, ...] = (0.0,) * 9
    localized: bool = False
    roll: Angle = 0.0
    pitch: Angle = 0.0
    tilted: bool = False


class Leg(msgspec.Struct, frozen=True, kw_only=True):
    """A straight leg in the ``field`` frame from (x0, y0) to (x1, y1), metres.

    ``final_yaw`` is the heading to rotate to in place on arrival (the next leg's
    direction); ``None`` keeps the arrival heading. ``scan_id`` marks a leg that ends
    at a scan location.
    """

    x0: Coordinate
    y0: Coordinate
    x1: Coordinate
    y1: Coordinate
    final_yaw: Angle | None = None
    scan_id: int | None = None

    @property
    def length(self) -> float:
        return math.hypot(self.x1 - self.x0, self.y1 - self.y0)


def legs_length(legs: list[Leg]) -> float:
    """Total driven length of ``legs`` in metres."""
    return float(sum(g.length for g in legs))


def round_trip_halves(legs: list[Leg]) -> tuple[list[Leg], list[Leg]]:
    """A round trip from the Origin (a plan's ``via_origin``) cut at its location, the
    leg that carries a scan id: (the way there, the way back)."""
    k = next(i for i, g in enumerate(legs) if g.scan_id is not None)
    return legs[: k + 1], legs[k + 1 :]


#: how far from a route's end (m) its follower may stop and still have arrived, unless
#: the route says otherwise: a scan location's, the mission's ``arrival_tolerance_m``
ARRIVAL_TOLERANCE_M = 0.05
#: an arrival tolerance (m), as a route carries it and a mission's config gives it
ArrivalTolerance = Annotated[float, msgspec.Meta(gt=0, le=100.0)]


class FollowRoute(msgspec.Struct, frozen=True, tag=True):
    """Follow ``legs``. The route holds for ``lease_s`` seconds (on navigation's clock)
    and must be renewed (:class:`RenewRoute`) before that, or the robot stops: whoever
    commands a route supervises it, and a supervisor that dies stops the robot.

    ``join``: start on the first leg that passes within the follower's join distance
    of the robot instead of the first leg, so a route re-sent after a restart
    continues where the robot stands rather than driving back to its start.

    ``arrival_tolerance_m``: the route has arrived only when the estimate is this close
    to its end; else it fails (a scan must never be taken where the robot merely
    stopped). Its sender knows what its goal needs, so the route carries it.

    ``to_scan``: the route ends at a scan location, so it ends with fine positioning
    and arrives only at its planned heading. A route that leads nowhere a scan is taken
    (the way back to the Origin, to a battery swap) sends ``to_scan=False``: it ends
    where its last leg does, within ``arrival_tolerance_m``, at any heading; time
    spent there on centimetres would buy nothing."""

    route_id: str
    legs: list[Leg]
    max_speed: Annotated[float, msgspec.Meta(gt=0, le=2.0)] = 0.5
    lease_s: Annotated[float, msgspec.Meta(gt=0, le=3600.0)] = 2.0
    join: bool = False
    arrival_tolerance_m: ArrivalTolerance = ARRIVAL_TOLERANCE_M
    to_scan: bool = True


class CancelRoute(msgspec.Struct, frozen=True, tag=True):
    route_id: str = ""


class RenewRoute(msgspec.Struct, frozen=True, tag=True):
    """Extend route ``route_id``'s lease by ``lease_s`` seconds from now. Navigation
    answers ``accepted=False`` when it does not follow that route (it restarted, or
    the lease ran out): the supervisor then sends the route again."""

    route_id: str
    lease_s: Annotated[float, msgspec.Meta(gt=0, le=3600.0)] = 2.0


NavCommand = FollowRoute | CancelRoute | RenewRoute

#: how ``NavProgress.detail`` begins when a route stopped for want of its supervisor
#: (no renewal, or its liveliness token went): the supervisor, if alive, sends it again
LEASE_ENDED = "lease ended"


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
    # the route ended without reaching its goal within the arrival tolerance, or its
    # lease ran out; ``NavProgress.detail`` says which
    FAILED = "failed"


class NavProgress(Message, frozen=True, kw_only=True):
    """Route-following progress in the ``field`` frame (metres, radians)."""

    route_id: str
    state: NavState
    leg: int = 0
    legs: int = 0
    distance_to_go: NonNegative = 0.0
    cross_track: Finite = 0.0
    heading_error: Angle = 0.0
    detail: str = ""
