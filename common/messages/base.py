"""The mobile base: velocity commands, wheel odometry, the IMU, 2D lidar, e-stop."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import (
    Angle,
    Array,
    Coordinate,
    Finite,
    Message,
    NonNegative,
    Probability,
    Velocity,
)

# Hard bounds a command must satisfy to be accepted at all; the base's own limits
# (Husky A200: 1.0 m/s) are applied on top in its config.
Speed = Annotated[float, msgspec.Meta(ge=-5.0, le=5.0)]
TurnRate = Annotated[float, msgspec.Meta(ge=-10.0, le=10.0)]


class Twist(Message, frozen=True, kw_only=True):
    """Velocity command in base_link: ``linear_x`` m/s forward, ``angular_z`` rad/s CCW."""

    linear_x: Speed = 0.0
    angular_z: TurnRate = 0.0


class Odometry(Message, frozen=True, kw_only=True):
    """Wheel odometry: pose of base_link in ``odom`` (metres, radians) and body rates."""

    x: Coordinate
    y: Coordinate
    yaw: Angle
    v: Velocity
    w: Velocity
    # variances of the increments per metre travelled / per radian turned
    var_v: NonNegative = 0.0
    var_w: NonNegative = 0.0


Accel = Annotated[float, msgspec.Meta(ge=-1000.0, le=1000.0)]


class Imu(Message, frozen=True, kw_only=True):
    """An attitude and heading reference system's output, as the Husky's UM7 driver
    fills sensor_msgs/Imu: the IMU frame's orientation in ZYX Euler angles (rad;
    roll and pitch against gravity from the unit's own filter, yaw from its
    magnetometer and not to be trusted beside the motors), its angular velocity
    (rad/s) and specific force (m/s^2, gravity included), in the IMU frame.
    ``tilt_var``: the variance the unit states for roll and pitch (rad^2)."""

    roll: Angle
    pitch: Angle
    yaw: Angle
    wx: Velocity = 0.0
    wy: Velocity = 0.0
    wz: Velocity = 0.0
    ax: Accel = 0.0
    ay: Accel = 0.0
    az: Accel = 9.80665
    tilt_var: NonNegative = 0.0


class LaserScan(Message, frozen=True, kw_only=True):
    """A planar scan (sensor_msgs/LaserScan): ``ranges`` float32 metres, inf = no return."""

    angle_min: Angle
    angle_max: Angle
    angle_increment: Angle
    range_min: NonNegative
    range_max: NonNegative
    ranges: Array


class EStop(Message, frozen=True, kw_only=True):
    """Emergency stop request: while ``asserted`` the base ignores velocity commands."""

    asserted: bool
    reason: str = ""


class BaseStatus(Message, frozen=True, kw_only=True):
    """Base driver state, published at the odometry rate."""

    stopped_by_watchdog: bool
    estop: bool
    battery_v: NonNegative = 0.0


class BatteryState(Message, frozen=True, kw_only=True):
    """The battery as the base's driver reports it (sensor_msgs/BatteryState: Clearpath's
    ``platform/bms/state``): ``percentage`` the charge left, 0-1; ``voltage`` (V) and
    ``current`` (A, negative while discharging), 0 where the driver gives none;
    ``present``: a battery is in. The base publishes it at about 1 Hz."""

    percentage: Probability
    voltage: NonNegative = 0.0
    current: Finite = 0.0
    present: bool = True
