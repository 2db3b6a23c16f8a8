"""The base service's ``ros2`` backend (rmw_zenoh layout) against a ROS 2 peer we did
not write: zenoh-ros2-sdk (pure-Python ROS 2 over rmw_zenoh, with its own key, type
hash, token and CDR code via rosbags) publishes Odometry, LaserScan and Imu that the
base turns into its own topics, subscribes the Twist the base sends, and lists the
base's topics from its liveliness tokens as ``ros2 topic list`` would; and it decodes
the sensor_msgs/Imu our node publishes (what the simulated Husky driver sends)."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zenoh_ros2_sdk.message_registry as sdk_registry
from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber
from zenoh_ros2_sdk.discovery import get_topic_names_and_types
from zenoh_ros2_sdk.session import ZenohSession

from common import keys
from common.client import wait_alive
from common.messages.base import Twist
from common.transport import Bus
from services.base.ros2 import msgs as ros
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import IMU
from services.base.ros2.wire import SENSOR_QOS
from tests.conftest import Procs, Record, record

MSGS = Path(__file__).resolve().parent.parent / "data" / "ros2_msgs"


@pytest.fixture
def sdk_port(router_endpoint: str, monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """The SDK's process-wide session, on the test router, listening on loopback only,
    reading .msg files from tests/data (it would fetch them from GitHub otherwise)."""
    monkeypatch.setenv("ZENOH_CONFIG_OVERRIDE", 'listen/endpoints=["tcp/127.0.0.1:0"]')
    sdk_registry._registry = None
    sdk_registry.get_registry(str(MSGS))
    ZenohSession._instance = None
    yield int(router_endpoint.rsplit(":", 1)[1])
    if ZenohSession._instance is not None:
        ZenohSession._instance.close()
    ZenohSession._instance = None
    sdk_registry._registry = None


def test_base_and_zenoh_ros2_sdk_interoperate(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path, sdk_port: int
) -> None:
    odom = record(client_bus, keys.BASE_ODOM)
    scans = record(client_bus, keys.BASE_SCAN)
    imus = record(client_bus, keys.BASE_IMU)
    procs.service(
        "services.base", router_endpoint, "--set", "backend=ros2", log=tmp_path / "base.log"
    )
    assert wait_alive(client_bus.session, {"base"}, timeout=20)

    odom_pub = ROS2Publisher("/odom", "nav_msgs/msg/Odometry", router_port=sdk_port)
    scan_pub = ROS2Publisher("/scan", "sensor_msgs/msg/LaserScan", router_port=sdk_port)
    imu_pub = ROS2Publisher("/imu/data", "sensor_msgs/msg/Imu", router_port=sdk_port)
    assert imu_pub.type_hash == IMU.type_hash  # the SDK's own RIHS01 of tests/data's .msg
    twists: list[Any] = []
    got_twist = threading.Condition()

    def on_twist(m: Any) -> None:
        with got_twist:
            twists.append(m)
            got_twist.notify_all()

    twist_sub = ROS2Subscriber(
        "/cmd_vel", "geometry_msgs/msg/Twist", on_twist, router_port=sdk_port
    )
    t = ZenohSession.get_instance().store.types

    def header(k: int, frame: str) -> Any:
        stamp = t["builtin_interfaces/msg/Time"](sec=100 + k, nanosec=500)
        return t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def odometry(k: int) -> dict[str, Any]:
        yaw = 0.5
        pose = t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=1.0 + k, y=2.0, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
            ),
        )
        vec = t["geometry_msgs/msg/Vector3"]
        tw = t["geometry_msgs/msg/Twist"](
            linear=vec(x=0.3, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=-0.1)
        )
        return {
            "header": header(k, "odom"),
            "child_frame_id": "base_link",
            "pose": t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            "twist": t["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)),
        }

    # the driver's odometry at 20 Hz: the test's input (the base stops the wheels
    # when it goes quiet), not a synchronisation
    stop = threading.Event()

    def drive() -> None:
        k = 0
        while not stop.wait(0.05):
            odom_pub.publish(**odometry(k))
            k += 1

    feeder = threading.Thread(target=drive, daemon=True)
    feeder.start()
    try:
        o = odom.wait_for(lambda o: o.x >= 1.0, timeout=10.0)
        assert o is not None, "the base never turned the SDK's Odometry into base/odom"
        assert (o.y, o.v, o.w) == (2.0, 0.3, -0.1) and math.isclose(o.yaw, 0.5)
        assert o.stamp_ns % 1_000_000_000 == 500

        for _ in range(50):
            scan_pub.publish(
                header=header(0, "laser"),
                angle_min=-1.0,
                angle_max=1.0,
                angle_increment=1.0,
                time_increment=0.0,
                scan_time=0.1,
                range_min=0.1,
                range_max=5.0,
                ranges=np.array([1.5, 9.0, 0.05], dtype=np.float32),
                intensities=np.zeros(0, dtype=np.float32),
            )
            if scans.until(lambda s: bool(s), timeout=0.1):
                break
        s = scans.wait_for(lambda s: s.frame_id == "laser", timeout=1.0)
        assert s is not None, "the base never turned the SDK's LaserScan into base/scan"
        r = s.ranges.numpy()
        assert r[0] == np.float32(1.5) and np.isinf(r[1]) and np.isinf(r[2])

        vec, quat = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
        q = ros.quaternion_of_euler(0.1, -0.05, 1.0)
        cov = np.array([1e-4, 0, 0, 0, 3e-4, 0, 0, 0, 0.01])
        for _ in range(50):
            imu_pub.publish(
                header=header(0, "imu_link"),
                orientation=quat(x=q.x, y=q.y, z=q.z, w=q.w),
                orientation_covariance=cov,
                angular_velocity=vec(x=0.01, y=0.0, z=0.2),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=vec(x=0.3, y=0.0, z=9.8),
                linear_acceleration_covariance=np.zeros(9),
            )
            if imus.until(bool, timeout=0.1):
                break
        i = imus.wait_for(lambda i: i.frame_id == "imu_link", timeout=1.0)
        assert i is not None, "the base never turned the SDK's Imu into base/imu"
        assert [i.roll, i.pitch, i.yaw] == pytest.approx([0.1, -0.05, 1.0], abs=1e-12)
        assert (i.wz, i.ax, i.az) == (0.2, 0.3, 9.8) and i.tilt_var == pytest.approx(2e-4)
        assert i.stamp_ns == 100 * 1_000_000_000 + 500

        cmd = client_bus.publisher(keys.BASE_CMD_VEL)
        assert cmd.wait_matched(10)
        with got_twist:
            for _ in range(100):
                cmd.put(Twist(linear_x=0.4, angular_z=0.2))
                if got_twist.wait_for(
                    lambda: any(m.linear.x == 0.4 and m.angular.z == 0.2 for m in twists),
                    timeout=0.1,
                ):
                    break
            assert any(m.linear.x == 0.4 for m in twists), "the SDK never received the Twist"

        # `ros2 topic list -t` as the SDK answers it from the liveliness tokens
        # (asked again until all four are listed: under load one query of 1 s can miss
        # tokens that are still arriving)
        want = {"/cmd_vel", "/odom", "/scan", "/imu/data"}
        deadline = time.monotonic() + 20.0
        while True:
            topics = dict(get_topic_names_and_types(router_port=sdk_port, timeout=1.0))
            if want <= topics.keys() or time.monotonic() > deadline:
                break
        assert want <= topics.keys(), sorted(topics)
        assert "geometry_msgs/msg/Twist" in topics["/cmd_vel"]
        assert "nav_msgs/msg/Odometry" in topics["/odom"]
        assert "sensor_msgs/msg/LaserScan" in topics["/scan"]
        assert "sensor_msgs/msg/Imu" in topics["/imu/data"]
    finally:
        stop.set()
        feeder.join()
        for h in (odom_pub, scan_pub, imu_pub, twist_sub):
            h.close()


def test_zenoh_ros2_sdk_decodes_our_imu(client_bus: Bus, sdk_port: int) -> None:
    got: Record[Any] = Record()
    sub = ROS2Subscriber("/imu/data", "sensor_msgs/msg/Imu", got.add, router_port=sdk_port)
    node = Ros2Node(client_bus.session, "husky_node")
    pub = node.publisher("imu/data", IMU, qos=SENSOR_QOS)
    msg = ros.imu(
        7_000_000_123, "imu_link", (0.1, -0.2, 3.0), (0.01, -0.02, 0.3), (0.5, -0.1, 9.7),
        2e-4, yaw_var=7e-3, angular_velocity_var=4e-4, linear_acceleration_var=1e-2,
    )  # fmt: skip
    try:
        for _ in range(100):  # until the SDK's subscription is matched
            pub.put(msg)
            if got.until(bool, timeout=0.1):
                break
        m = got.wait_for(lambda m: True, timeout=1.0)
        assert m is not None, "the SDK never decoded our sensor_msgs/Imu"
        assert (m.header.stamp.sec, m.header.stamp.nanosec) == (7, 123)
        assert m.header.frame_id == "imu_link"
        o = m.orientation
        assert (o.x, o.y, o.z, o.w) == (
            msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w,
        )  # fmt: skip
        assert list(m.orientation_covariance) == [2e-4, 0, 0, 0, 2e-4, 0, 0, 0, 7e-3]
        assert (m.angular_velocity.z, m.linear_acceleration.z) == (0.3, 9.7)
        assert list(m.linear_acceleration_covariance)[::4] == [1e-2] * 3
    finally:
        sub.close()
        node.close()
