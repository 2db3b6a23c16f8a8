"""Base backends: what drives the wheels and where odometry and the 2D lidar come
from. ``BACKENDS`` maps the config's ``backend`` to a class."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from common import keys
from common.messages.base import LaserScan
from common.messages.core import Array
from common.messages.sim import SimWheelCommand
from common.transport import Bus
from services.base import ros2_msgs as ros
from services.base.config import BaseConfig

# (stamp_ns, v, w) from the wheel encoders
EncoderCallback = Callable[[int, float, float], None]
# a ready odometry pose from the base itself: (stamp_ns, x, y, yaw, v, w)
OdomCallback = Callable[[int, float, float, float, float, float], None]


class Drive(Protocol):
    def send(self, v: float, w: float, stamp_ns: int) -> None:
        """Drive the wheels at body velocities v (m/s), w (rad/s)."""
        ...


class SimBase:
    """The simulator's Husky: wheel commands out, encoders and lidar in."""

    def __init__(
        self,
        cfg: BaseConfig,
        bus: Bus,
        on_encoders: EncoderCallback,
        on_odom: OdomCallback,
        on_scan: Callable[[LaserScan], None],
    ) -> None:
        self._wheels = bus.publisher(keys.SIM_WHEELS)
        bus.subscribe(keys.SIM_ENCODERS, lambda m: on_encoders(m.stamp_ns, m.v, m.w))
        bus.subscribe(keys.SIM_LIDAR, on_scan)

    def send(self, v: float, w: float, stamp_ns: int) -> None:
        self._wheels.put(SimWheelCommand(stamp_ns=stamp_ns, v=v, w=w))


def decode_odometry(data: bytes) -> ros.Odometry:
    return ros.Odometry.deserialize(data)


def decode_scan(data: bytes) -> ros.LaserScan:
    return ros.LaserScan.deserialize(data)


def scan_from_ros(m: ros.LaserScan) -> LaserScan:
    ranges = np.asarray(m.ranges, dtype=np.float32)
    # REP-117: below range_min or above range_max is "no return"
    ranges = np.where((ranges < m.range_min) | (ranges > m.range_max), np.inf, ranges)
    return LaserScan(
        stamp_ns=m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec,
        frame_id=m.header.frame_id,
        angle_min=m.angle_min,
        angle_max=m.angle_max,
        angle_increment=m.angle_increment,
        range_min=max(0.0, m.range_min),
        range_max=max(0.0, m.range_max),
        ranges=Array.of(ranges.astype(np.float32)),
    )


class Ros2Base:
    """Any ROS 2 base through zenoh-bridge-ros2dds: the bridge maps ROS topic
    ``/cmd_vel`` to the Zenoh key ``cmd_vel`` (and so on), payloads in CDR."""

    def __init__(
        self,
        cfg: BaseConfig,
        bus: Bus,
        on_encoders: EncoderCallback,
        on_odom: OdomCallback,
        on_scan: Callable[[LaserScan], None],
    ) -> None:
        self._bus = bus
        self._cmd_key = cfg.ros2_cmd_vel

        def odom(m: ros.Odometry) -> None:
            st = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            p, t = m.pose.pose, m.twist.twist
            on_odom(
                st, p.position.x, p.position.y, ros.yaw_of(p.orientation), t.linear.x, t.angular.z
            )

        bus.subscribe_raw(cfg.ros2_odom, decode_odometry, odom)
        bus.subscribe_raw(cfg.ros2_scan, decode_scan, lambda m: on_scan(scan_from_ros(m)))

    def send(self, v: float, w: float, stamp_ns: int) -> None:
        if not (math.isfinite(v) and math.isfinite(w)):
            v = w = 0.0
        self._bus.put_raw(self._cmd_key, ros.twist(v, w).serialize())


BACKENDS: dict[str, type[SimBase] | type[Ros2Base]] = {"sim": SimBase, "ros2": Ros2Base}
