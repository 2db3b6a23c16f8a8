"""ROS 2 messages into the bus's: what the ``ros2`` backend takes from a base's
driver, checked, so a value every subscriber would refuse never reaches the bus."""

from __future__ import annotations

import math

import msgspec
import numpy as np

from common.messages.base import BatteryState, Imu, LaserScan, Odometry
from common.messages.core import Array
from services.base.ros2 import msgs as ros


def decode_odometry(data: bytes) -> ros.Odometry:
    return ros.Odometry.deserialize(data)


def decode_scan(data: bytes) -> ros.LaserScan:
    return ros.LaserScan.deserialize(data)


def decode_imu(data: bytes) -> ros.Imu:
    return ros.Imu.deserialize(data)


def decode_battery(data: bytes) -> ros.BatteryState:
    return ros.BatteryState.deserialize(data)


Odom = tuple[int, float, float, float, float, float]
# the bus Odometry's fields in nav_msgs/Odometry
_ODOM_FIELDS = {
    "x": "pose.pose.position.x",
    "y": "pose.pose.position.y",
    "v": "twist.twist.linear.x",
    "w": "twist.twist.angular.z",
}


def odom_from_ros(m: ros.Odometry) -> Odom:
    """(stamp ns, x, y, yaw, v, w) of a nav_msgs/Odometry, in the ``odom`` frame.
    Raises ValueError naming the field when a value is not finite or is outside the
    bus Odometry's bounds (navigation would integrate it into every pose after, and
    every subscriber would refuse it on decode)."""
    p, t = m.pose.pose, m.twist.twist
    fields = {
        "x": p.position.x,
        "y": p.position.y,
        "yaw": _euler("pose.pose.orientation", p.orientation)[2],
        "v": t.linear.x,
        "w": t.angular.z,
    }
    # the constructor does not check the schema's bounds (finite included): convert does
    try:
        o = msgspec.convert(fields, Odometry)
    except msgspec.ValidationError as exc:  # "... - at `$.x`": named as the driver has it
        at = str(exc).rpartition("`$.")[2].rstrip("`")
        raise ValueError(f"odometry {_ODOM_FIELDS.get(at, at)}: {exc}") from None
    return ros.ns_of_time(m.header.stamp), o.x, o.y, o.yaw, o.v, o.w


def _euler(name: str, q: ros.Quaternion) -> tuple[float, float, float]:
    """:func:`.ros2.msgs.euler_of`, its ValueError naming the field ``name``."""
    try:
        return ros.euler_of(q)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def imu_from_ros(m: ros.Imu) -> Imu:
    """The bus message of a sensor_msgs/Imu: orientation as ZYX Euler angles,
    ``tilt_var`` the mean of the roll and pitch variances the driver states. Raises
    ValueError naming the field when the message holds no orientation (sensor_msgs:
    a first covariance element of -1; navigation would take its zero quaternion for a
    level robot), or a value is not finite or is outside the bus message's bounds
    (which every subscriber would refuse on decode)."""
    q = m.orientation
    var_roll, var_pitch = (float(v) for v in np.asarray(m.orientation_covariance)[[0, 4]])
    if var_roll < 0.0:
        raise ValueError("orientation_covariance[0] < 0: the IMU states no orientation")
    roll, pitch, yaw = _euler("orientation", q)
    tilt_var = 0.5 * (var_roll + max(var_pitch, 0.0))
    w, a = m.angular_velocity, m.linear_acceleration
    fields = {
        "stamp_ns": ros.ns_of_time(m.header.stamp),
        "frame_id": m.header.frame_id,
        "roll": roll,
        "pitch": pitch,
        "yaw": yaw,
        "wx": w.x,
        "wy": w.y,
        "wz": w.z,
        "ax": a.x,
        "ay": a.y,
        "az": a.z,
        "tilt_var": tilt_var,
    }
    # the constructor does not check the schema's bounds (finite included): convert does
    return msgspec.convert(fields, Imu)


def scan_from_ros(m: ros.LaserScan) -> LaserScan:
    ranges = np.asarray(m.ranges, dtype=np.float32)
    # REP-117: below range_min or above range_max is "no return"
    ranges = np.where((ranges < m.range_min) | (ranges > m.range_max), np.inf, ranges)
    return LaserScan(
        stamp_ns=ros.ns_of_time(m.header.stamp),
        frame_id=m.header.frame_id,
        angle_min=m.angle_min,
        angle_max=m.angle_max,
        angle_increment=m.angle_increment,
        range_min=max(0.0, m.range_min),
        range_max=max(0.0, m.range_max),
        ranges=Array.of(ranges.astype(np.float32)),
    )


def battery_from_ros(m: ros.BatteryState) -> BatteryState:
    """The bus message of a sensor_msgs/BatteryState: the charge from ``percentage``
    (0-1), or from ``charge`` / ``capacity`` where the driver leaves the percentage
    NaN; an unmeasured voltage or current (NaN) is 0. Raises ValueError naming the
    field when neither gives a charge, or the percentage is outside 0-1 (a driver
    that publishes 0-100 would otherwise read as a full battery)."""
    pct = float(m.percentage)
    if not math.isfinite(pct):
        charge, capacity = float(m.charge), float(m.capacity)
        if not (math.isfinite(charge) and math.isfinite(capacity) and capacity > 0):
            raise ValueError("percentage is NaN and charge / capacity give none")
        pct = min(max(charge / capacity, 0.0), 1.0)
    if not 0.0 <= pct <= 1.0:
        raise ValueError(f"percentage {pct:g} is outside 0-1 (sensor_msgs: a fraction)")

    def measured(x: float) -> float:
        return float(x) if math.isfinite(x) else 0.0

    return BatteryState(
        stamp_ns=ros.ns_of_time(m.header.stamp),
        frame_id=m.header.frame_id,
        percentage=pct,
        voltage=max(0.0, measured(m.voltage)),
        current=measured(m.current),
        present=bool(m.present),
    )
