"""rmw_zenoh's wire (services.base.ros2) against implementations we did not write: rosbags'
type store (RIHS01 hashes, CDR), zenoh-ext's serializer (the attachment, as zenoh-cpp
writes it for rmw_zenoh) and zenoh-ros2-sdk's key and token builders; then a node on
loopback that drops bad samples without raising."""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np
import pytest
import zenoh
import zenoh.ext as zext
from rosbags.typesys import Stores, get_typestore
from zenoh_ros2_sdk.attachment import Attachment as SdkAttachment
from zenoh_ros2_sdk.entity import EndpointEntity, EntityKind, NodeEntity
from zenoh_ros2_sdk.keyexpr import endpoint_liveliness_keyexpr, node_liveliness_keyexpr

from services.base.ros2 import msgs as ros
from services.base.ros2 import wire
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import (
    BATTERY_STATE,
    IMU,
    LASER_SCAN,
    ODOMETRY,
    TWIST,
    TWIST_STAMPED,
    RosType,
)

JAZZY = get_typestore(Stores.ROS2_JAZZY)
ZID = "4b33868af7b46327b80673b0f621d09b"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"


@pytest.mark.parametrize(
    "rtype",
    [TWIST, TWIST_STAMPED, ODOMETRY, LASER_SCAN, IMU, BATTERY_STATE],
    ids=lambda t: t.name,
)
def test_type_hashes_are_rosbags_rihs01(rtype: RosType[object]) -> None:
    assert rtype.type_hash == JAZZY.hash_rihs01(rtype.name)


def test_topic_keys() -> None:
    assert wire.dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"
    assert (
        wire.topic_key(0, "/cmd_vel", TWIST.name, TWIST.type_hash)
        == f"0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}"
    )
    fq = wire.fully_qualified("/husky", "odom")
    assert fq == "/husky/odom"
    assert (
        wire.topic_key(7, fq, ODOMETRY.name, "H") == "7/husky/odom/nav_msgs::msg::dds_::Odometry_/H"
    )
    assert wire.fully_qualified("/husky", "/scan") == "/scan"
    assert wire.fully_qualified("/", "cmd_vel") == "/cmd_vel"
    for bad_ns, bad_topic in [("husky", "odom"), ("/", "~/odom"), ("/", "a//b"), ("/a/", "b")]:
        with pytest.raises(wire.WireError):
            wire.fully_qualified(bad_ns, bad_topic)


def test_qos_strings() -> None:
    # rclcpp's default QoS(10) and SensorDataQoS, as rmw_zenoh 0.2.x writes them
    assert wire.qos_string(wire.Qos()) == "::,10:,:,:,,"
    assert wire.qos_string(wire.SENSOR_QOS) == "2::,5:,:,:,,"
    assert wire.qos_string(wire.Qos(transient_local=True, depth=1)) == ":1:,1:,:,:,,"
    assert wire.qos_string(wire.Qos(depth=42)) == "::,:,:,:,,"


def test_liveliness_tokens() -> None:
    node = wire.node_token(0, ZID, 3, "/", "husky_node")
    assert node == f"@ros2_lv/0/{ZID}/3/3/NN/%/%/husky_node"
    pub = wire.endpoint_token(
        "MP", 0, ZID, 3, 4, "/husky", "husky_node", "/husky/odom", ODOMETRY.name,
        ODOMETRY.type_hash, wire.Qos(),
    )  # fmt: skip
    assert pub == (
        f"@ros2_lv/0/{ZID}/3/4/MP/%/%husky/husky_node/%husky%odom/"
        f"nav_msgs::msg::dds_::Odometry_/{ODOMETRY.type_hash}/::,10:,:,:,,"
    )
    # rmw_zenoh's Entity::make(keyexpr) wants 13 parts, none empty, and a key Zenoh takes
    parts = pub.split("/")
    assert len(parts) == 13 and all(parts)
    zenoh.KeyExpr(pub)
    with pytest.raises(wire.WireError):
        wire.node_token(0, ZID, 3, "/", "a/b")


def test_tokens_equal_zenoh_ros2_sdk() -> None:
    node = NodeEntity(domain_id=0, session_id=ZID, node_id=3, node_name="base", namespace="/")
    assert wire.node_token(0, ZID, 3, "/", "base") == node_liveliness_keyexpr(node)
    ep = EndpointEntity(
        node=node,
        entity_id=5,
        kind=EntityKind.SUBSCRIPTION,
        name="/scan",
        dds_type_name=LASER_SCAN.dds_name,
        type_hash=LASER_SCAN.type_hash,
        qos=wire.qos_string(wire.SENSOR_QOS),
    )
    ours = wire.endpoint_token(
        "MS", 0, ZID, 3, 5, "/", "base", "/scan", LASER_SCAN.name, LASER_SCAN.type_hash,
        wire.SENSOR_QOS,
    )  # fmt: skip
    assert ours == endpoint_liveliness_keyexpr(ep)


def test_attachment_is_zenoh_ext_serialization() -> None:
    gid = bytes(range(16))
    att = wire.Attachment(42, 1_700_000_000_123_456_789, gid)
    data = att.encode()
    # what zenoh-cpp's Serializer writes for (int64, int64, std::array<uint8_t, 16>)
    ref = zext.z_serialize((zext.Int64(42), zext.Int64(1_700_000_000_123_456_789), gid))
    assert data == ref.to_bytes() and len(data) == wire.ATTACHMENT_SIZE
    assert wire.Attachment.decode(data) == att
    s = SdkAttachment.from_bytes(data)
    assert (s.sequence_id, s.timestamp_ns, s.gid) == (42, att.source_timestamp_ns, gid)
    seq, ts, g = zext.z_deserialize(tuple[zext.Int64, zext.Int64, bytes], ref)
    assert (int(seq), int(ts), g) == (42, att.source_timestamp_ns, gid)


@pytest.mark.parametrize(
    "bad",
    [
        b"",
        b"\x01" * 17,
        b"\x00" * 16 + b"\x0f" + b"\x00" * 16,
        b"\x00" * 16 + b"\x10" + b"\x00" * 17,
    ],
    ids=["empty", "short", "gid-length", "trailing"],
)
def test_bad_attachment_is_refused(bad: bytes) -> None:
    with pytest.raises(wire.WireError):
        wire.Attachment.decode(bad)


def test_cdr_payloads_are_rosbags_cdr() -> None:
    cov = [float(i) for i in range(36)]
    odom = ros.odometry(
        1_700_000_000_250_000_000, "odom", "base_link", (1.5, -2.0, 0.3), (0.4, 0.1), cov, cov[::-1]
    )
    back: Any = JAZZY.deserialize_cdr(ODOMETRY.encode(odom), ODOMETRY.name)
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert back.header.frame_id == "odom" and back.child_frame_id == "base_link"
    p = back.pose.pose
    assert (p.position.x, p.position.y) == (1.5, -2.0)
    assert math.isclose(2 * math.atan2(p.orientation.z, p.orientation.w), 0.3)
    assert list(back.pose.covariance) == cov and list(back.twist.covariance) == cov[::-1]
    assert (back.twist.twist.linear.x, back.twist.twist.angular.z) == (0.4, 0.1)

    ranges = [1.0, math.inf, 0.25]
    scan = ros.laser_scan(5, "laser", (-2.0, 2.0, 2.0), (0.06, 5.0), ranges)
    back = JAZZY.deserialize_cdr(LASER_SCAN.encode(scan), LASER_SCAN.name)
    assert back.header.frame_id == "laser" and back.ranges.dtype == np.float32
    assert list(back.ranges) == ranges and len(back.intensities) == 0
    assert np.float32(back.range_min) == np.float32(0.06)

    tw: Any = JAZZY.deserialize_cdr(TWIST.encode(ros.twist(0.5, -0.25)), TWIST.name)
    assert (tw.linear.x, tw.angular.z) == (0.5, -0.25)


def test_rosbags_cdr_decodes_here() -> None:
    t = JAZZY.types
    m = t["nav_msgs/msg/Odometry"](
        header=t["std_msgs/msg/Header"](
            stamp=t["builtin_interfaces/msg/Time"](sec=3, nanosec=7), frame_id="odom"
        ),
        child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
            covariance=np.arange(36, dtype=np.float64),
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=t["geometry_msgs/msg/Vector3"](x=0.4, y=0.0, z=0.0),
                angular=t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.2),
            ),
            covariance=np.zeros(36),
        ),
    )
    o = ODOMETRY.decode(bytes(JAZZY.serialize_cdr(m, ODOMETRY.name)))
    assert ros.ns_of_time(o.header.stamp) == 3_000_000_007 and o.child_frame_id == "base_link"
    assert o.pose.pose.position.y == 2.0 and o.twist.twist.angular.z == 0.2
    assert np.asarray(o.pose.covariance).tolist() == list(range(36))


def test_imu_cdr_is_rosbags_cdr() -> None:
    m = ros.imu(
        1_700_000_000_250_000_000, "imu_link", (0.1, -0.2, 3.0), (0.01, -0.02, 0.3),
        (0.5, -0.1, 9.7), 2e-4, yaw_var=7e-3, angular_velocity_var=4e-4,
        linear_acceleration_var=1e-2,
    )  # fmt: skip
    data = IMU.encode(m)
    back: Any = JAZZY.deserialize_cdr(data, IMU.name)
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (1_700_000_000, 250_000_000)
    assert back.header.frame_id == "imu_link"
    q, o = back.orientation, m.orientation
    assert (q.x, q.y, q.z, q.w) == (o.x, o.y, o.z, o.w)
    assert list(back.orientation_covariance) == [2e-4, 0, 0, 0, 2e-4, 0, 0, 0, 7e-3]
    assert (back.angular_velocity.x, back.angular_velocity.z) == (0.01, 0.3)
    assert list(back.angular_velocity_covariance)[::4] == [4e-4] * 3
    assert (back.linear_acceleration.y, back.linear_acceleration.z) == (-0.1, 9.7)
    assert list(back.linear_acceleration_covariance)[::4] == [1e-2] * 3
    # and back: rosbags' bytes are ours, byte for byte
    assert bytes(JAZZY.serialize_cdr(back, IMU.name)) == data
    again = IMU.decode(bytes(JAZZY.serialize_cdr(back, IMU.name)))
    assert ros.euler_of(again.orientation) == pytest.approx((0.1, -0.2, 3.0), abs=1e-12)


def test_battery_state_cdr_is_rosbags_cdr() -> None:
    data = BATTERY_STATE.encode(ros.battery_state(5_000_000_001, 0.625, 25.5, -4.0, 20.0))
    back: Any = JAZZY.deserialize_cdr(data, BATTERY_STATE.name)
    assert (back.header.stamp.sec, back.header.stamp.nanosec) == (5, 1)
    assert (back.percentage, back.voltage, back.current) == (0.625, 25.5, -4.0)
    assert (back.charge, back.capacity, back.present) == (12.5, 20.0, True)
    assert math.isnan(back.temperature) and back.power_supply_status == 2
    assert bytes(JAZZY.serialize_cdr(back, BATTERY_STATE.name)) == data


def test_node_drops_bad_samples_and_keeps_going(
    two_sessions: tuple[zenoh.Session, zenoh.Session],
) -> None:
    a, b = two_sessions
    got: list[ros.Twist] = []
    cond = threading.Condition()

    def on_twist(t: ros.Twist) -> None:
        with cond:
            got.append(t)
            cond.notify_all()

    sub = Ros2Node(a, "listener")
    key = sub.subscribe("cmd_vel", TWIST, on_twist)
    talker = Ros2Node(b, "talker")
    pub = talker.publisher("cmd_vel", TWIST)
    assert pub.key == key
    good = wire.Attachment(1, 0, bytes(16)).encode()

    def delivered(n: int) -> bool:
        with cond:
            return cond.wait_for(lambda: len(got) >= n, timeout=5.0)

    # the subscriber is matched once a first message gets through
    for _ in range(100):
        pub.put(ros.twist(0.1, 0.0))
        with cond:
            if cond.wait_for(lambda: bool(got), timeout=0.05):
                break
    n0 = len(got)
    b.put(key, TWIST.encode(ros.twist(9.0, 0.0)))  # no attachment
    b.put(key, TWIST.encode(ros.twist(9.0, 0.0)), attachment=b"\x01\x02")  # bad attachment
    b.put(key, b"\x00\x01\x00\x00\x01", attachment=good)  # truncated CDR
    pub.put(ros.twist(0.7, 0.0))
    assert delivered(n0 + 1)
    assert [t.linear.x for t in got[n0:]] == [0.7]
    assert sub.dropped == {key: 3} and sub.dropped_total == 3
    sub.close()
    talker.close()
