"""GNSS receiver output, after the ROS sensor_msgs/NavSatFix shape."""

from __future__ import annotations

import enum
from typing import Annotated

import msgspec

from common.messages.core import (
    Altitude,
    Angle,
    Finite,
    Latitude,
    Longitude,
    Message,
    NonNegative,
)


class FixType(enum.IntEnum):
    """Solution type, numbered as the NMEA GGA quality indicator (field 6)."""

    NO_FIX = 0
    SINGLE = 1
    DGPS = 2
    PPS = 3
    FIX = 4  # RTK fixed: integer ambiguities resolved, cm level
    FLOAT = 5  # RTK float: dm level
    ESTIMATED = 6  # dead reckoning
    MANUAL = 7
    SIMULATION = 8


class NavSatFix(Message, frozen=True, kw_only=True):
    """One antenna's position in WGS84 (degrees, metres above the ellipsoid).

    ``position_covariance`` is row-major 3x3 in ENU metres^2 at the antenna, as in ROS
    (finite by schema; whether it is a covariance at all, its consumer checks).
    ``frame_id`` is the antenna frame (``gnss_1``, ``gnss_2``).
    """

    antenna: Annotated[int, msgspec.Meta(ge=1, le=2)]
    latitude: Latitude
    longitude: Longitude
    altitude: Altitude
    fix_type: FixType
    position_covariance: tuple[Finite, ...] = (0.0,) * 9
    num_satellites: int = 0
    hdop: NonNegative = 0.0


class GnssHeading(Message, frozen=True, kw_only=True):
    """The GNSS-compass heading of base_link in the ``field`` frame (REP-103: 0 along
    +x, counter-clockwise), from the two antennas (paper eq. 2).

    ``valid`` is false when either antenna lacks an RTK fix or the measured baseline
    disagrees with the mounted one.
    """

    yaw: Angle
    yaw_sd: NonNegative
    baseline_m: NonNegative
    valid: bool
