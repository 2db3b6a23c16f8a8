"""The ros2 backend's CDR: byte layouts checked against ROS 2's wire format, and
decoding of the messages a Husky driver publishes."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from services.base.ros2 import msgs as ros
from services.base.ros2.types import IMU
from services.base.ros2_convert import decode_odometry, scan_from_ros


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


def test_imu_bytes_are_ros2_cdr_and_round_trip() -> None:
    m = ros.imu(
        2_000_000_300, "imu_link", (0.1, -0.2, 0.3), (0.01, 0.02, 0.03), (0.4, 0.5, 9.8), 1e-4,
        yaw_var=7e-3, angular_velocity_var=4e-4, linear_acceleration_var=1e-2,
    )  # fmt: skip
    data = IMU.encode(m)
    # header (stamp, frame_id "imu_link" + NUL), padded to 8, then 4 + 9 + 3 + 9 + 3 + 9
    # float64
    frame = b"imu_link\x00"
    head = b"\x00\x01\x00\x00" + struct.pack("<iII", 2, 300, len(frame)) + frame
    head += b"\x00" * (-len(head[4:]) % 8)
    assert data[: len(head)] == head and len(data) == len(head) + 37 * 8
    f = struct.unpack_from("<37d", data, len(head))
    q = f[0:4]
    assert math.isclose(math.fsum(c * c for c in q), 1.0)
    assert f[4:13] == (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 7e-3)
    assert f[13:16] == (0.01, 0.02, 0.03) and f[16:25][::4] == (4e-4,) * 3
    assert f[25:28] == (0.4, 0.5, 9.8) and f[28:37][::4] == (1e-2,) * 3
    back = IMU.decode(data)
    assert back == ros.Imu.deserialize(data)
    assert back.header.frame_id == "imu_link" and ros.ns_of_time(back.header.stamp) == 2_000_000_300
    cov = np.asarray(back.orientation_covariance).tolist()
    assert cov == np.asarray(m.orientation_covariance).tolist()
    assert ros.euler_of(back.orientation) == pytest.approx((0.1, -0.2, 0.3), abs=1e-12)


@pytest.mark.parametrize(
    "rpy",
    [(0.0, 0.0, 0.0), (0.1, -0.2, 0.3), (-3.0, 1.2, -2.9), (0.5, -1.5, 3.1), (3.14, 0.0, -3.14)],
)
def test_euler_round_trips_through_quaternion(rpy: tuple[float, float, float]) -> None:
    q = ros.quaternion_of_euler(*rpy)
    assert ros.euler_of(q) == pytest.approx(rpy, abs=1e-9)
    # yaw alone agrees with the planar helpers; a scaled quaternion is the same rotation
    assert ros.quaternion_of_euler(0.0, 0.0, rpy[2]) == ros.quaternion_of_yaw(rpy[2])
    assert math.isclose(ros.yaw_of(ros.quaternion_of_yaw(rpy[2])), rpy[2], abs_tol=1e-12)
    scaled = ros.Quaternion(2 * q.x, 2 * q.y, 2 * q.z, 2 * q.w)
    assert ros.euler_of(scaled) == pytest.approx(rpy, abs=1e-9)


def test_euler_of_a_known_rotation() -> None:
    # 45 deg about y is pitch alone; a zero quaternion reads as no rotation
    q = ros.Quaternion(0.0, math.sin(math.pi / 8), 0.0, math.cos(math.pi / 8))
    assert ros.euler_of(q) == pytest.approx((0.0, math.pi / 4, 0.0))
    assert ros.euler_of(ros.Quaternion(0.0, 0.0, 0.0, 0.0)) == (0.0, 0.0, 0.0)
