"""The ros2 backend's CDR: byte layouts checked against ROS 2's wire format, and
decoding of the messages a Husky driver publishes."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from common.ros2 import msgs as ros
from services.base.backends import decode_odometry, scan_from_ros


def test_twist_bytes_are_ros2_cdr() -> None:
    data = ros.twist(0.5, -0.25).serialize()
    # CDR little-endian encapsulation header, then six float64
    assert data[:4] == b"\x00\x01\x00\x00"
    assert struct.unpack("<6d", data[4:]) == (0.5, 0.0, 0.0, 0.0, 0.0, -0.25)


def test_odometry_decodes_from_hand_built_cdr() -> None:
    # nav_msgs/Odometry as a ROS 2 node would send it, packed field by field
    frame, child = b"odom\x00", b"base_link\x00"
    buf = bytearray(b"\x00\x01\x00\x00")
    buf += struct.pack("<iI", 12, 500)  # stamp
    buf += struct.pack("<I", len(frame)) + frame
    buf += b"\x00" * (-len(buf[4:]) % 4)
    buf += struct.pack("<I", len(child)) + child
    buf += b"\x00" * (-len(buf[4:]) % 8)  # align to 8 for float64
    yaw = 0.3
    buf += struct.pack("<7d", 1.0, 2.0, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    buf += struct.pack("<36d", *([0.01] * 36))
    buf += struct.pack("<6d", 0.4, 0.0, 0.0, 0.0, 0.0, 0.1)
    buf += struct.pack("<36d", *([0.0] * 36))
    m = decode_odometry(bytes(buf))
    assert m.header.stamp.sec == 12 and m.header.frame_id == "odom"
    assert m.child_frame_id == "base_link"
    assert m.pose.pose.position.x == 1.0 and m.twist.twist.linear.x == 0.4
    assert math.isclose(ros.yaw_of(m.pose.pose.orientation), yaw)


def test_truncated_odometry_raises() -> None:
    with pytest.raises(Exception):  # noqa: B017 - any decode failure is dropped upstream
        decode_odometry(b"\x00\x01\x00\x00\x01\x02")


def test_laser_scan_out_of_range_becomes_inf() -> None:
    m = ros.LaserScan(
        header=ros.Header(ros.Time(1, 0), "laser"),
        angle_min=-2.35,
        angle_max=2.35,
        angle_increment=0.0043,
        time_increment=0.0,
        scan_time=0.025,
        range_min=0.06,
        range_max=5.0,
        ranges=[1.0, 0.01, 7.0, 4.9],  # type: ignore[arg-type]
        intensities=[],  # type: ignore[arg-type]
    )
    back = ros.LaserScan.deserialize(m.serialize())
    scan = scan_from_ros(back)
    r = scan.ranges.numpy()
    assert r[0] == pytest.approx(1.0) and np.isinf(r[1]) and np.isinf(r[2])
    assert r[3] == pytest.approx(4.9) and scan.frame_id == "laser"
