"""The simulated Husky ROS 2 driver and the base service's ``ros2`` backend as
processes, with the test as the simulator (encoders, lidar and IMU in, wheels out):
the base's odometry, scans and IMU come through the driver, its commands reach the
simulated wheels, and a silent driver stops them."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from common import keys
from common.client import wait_alive
from common.config import zenoh_config
from common.messages.base import Imu, LaserScan, Twist
from common.messages.core import Array
from common.messages.sim import SimEncoders
from common.transport import Bus
from services.base.ros2 import msgs as ros
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import IMU, ODOMETRY, TWIST
from services.base.sim.husky import HUSKY_COVARIANCE, IMU_YAW_VAR
from tests.conftest import Procs, Record, record


def test_base_drives_the_simulated_husky(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    odom = record(client_bus, keys.BASE_ODOM)
    scans = record(client_bus, keys.BASE_SCAN)
    imus = record(client_bus, keys.BASE_IMU)
    wheels = record(client_bus, keys.SIM_WHEELS)
    health = record(client_bus, keys.HEALTH.at(service="base"))
    husky = procs.service("services.base.sim.husky", router_endpoint, log=tmp_path / "husky.log")
    base = procs.service(
        "services.base", router_endpoint, "--set", "backend=ros2", log=tmp_path / "base.log"
    )
    assert wait_alive(client_bus.session, {"base", "husky-sim"}, timeout=20)

    # a ROS 2 tool's view: the driver's odometry and the base's commands on the wire
    spy_session = zenoh.open(zenoh_config("peer", ["tcp/127.0.0.1:0"], [router_endpoint]))
    spy = Ros2Node(spy_session, "spy")
    ros_odom: Record[ros.Odometry] = Record()
    ros_cmd: Record[ros.Twist] = Record()
    ros_imu: Record[ros.Imu] = Record()
    spy.subscribe("odom", ODOMETRY, ros_odom.add)
    spy.subscribe("imu/data", IMU, ros_imu.add)
    spy.subscribe("cmd_vel", TWIST, ros_cmd.add)

    # the simulator's encoders at 20 Hz, 1 m/s straight (the test's input)
    enc = client_bus.publisher(keys.SIM_ENCODERS)
    stop = threading.Event()

    def encoders() -> None:
        k = 0
        while not stop.wait(0.05):
            enc.put(SimEncoders(stamp_ns=k * 50_000_000, v=1.0, w=0.0))
            k += 1

    feeder = threading.Thread(target=encoders, daemon=True)
    feeder.start()
    try:
        o = odom.wait_for(lambda o: o.x > 0.2, timeout=10.0)
        assert o is not None and o.v == 1.0 and o.frame_id == "odom"
        r = ros_odom.wait_for(lambda m: m.pose.pose.position.x > 0.2, timeout=2.0)
        assert r is not None and r.child_frame_id == "base_link"
        assert np.asarray(r.pose.covariance).tolist()[::7] == list(HUSKY_COVARIANCE)

        lidar = client_bus.publisher(keys.SIM_LIDAR)
        ranges = np.array([2.0, np.inf], dtype=np.float32)
        for _ in range(50):
            lidar.put(
                LaserScan(
                    stamp_ns=1,
                    frame_id="lidar",
                    angle_min=-0.5,
                    angle_max=0.5,
                    angle_increment=1.0,
                    range_min=0.06,
                    range_max=5.0,
                    ranges=Array.of(ranges),
                )
            )
            if scans.until(bool, timeout=0.1):
                break
        s = scans.wait_for(lambda s: s.frame_id == "lidar", timeout=1.0)
        assert s is not None and s.ranges.numpy()[0] == 2.0 and np.isinf(s.ranges.numpy()[1])

        # sim/device/imu -> the driver's imu/data (sensor_msgs/Imu) -> base/imu
        imu = client_bus.publisher(keys.SIM_IMU)
        sim_imu = Imu(
            stamp_ns=1, frame_id="imu_link", roll=0.05, pitch=-0.1, yaw=2.0,
            wx=0.01, wy=-0.02, wz=0.3, ax=0.2, ay=-0.1, az=9.8, tilt_var=3e-4,
        )  # fmt: skip
        for _ in range(50):
            imu.put(sim_imu)
            if imus.until(bool, timeout=0.1):
                break
        i = imus.wait_for(lambda i: i.frame_id == "imu_link", timeout=1.0)
        assert i is not None, "the simulator's IMU never reached base/imu"
        assert [i.roll, i.pitch, i.yaw] == pytest.approx([0.05, -0.1, 2.0], abs=1e-12)
        assert (i.wx, i.wy, i.wz, i.ax, i.ay, i.az) == (0.01, -0.02, 0.3, 0.2, -0.1, 9.8)
        assert i.tilt_var == pytest.approx(3e-4) and i.stamp_ns > 1  # the driver's stamp
        ri = ros_imu.wait_for(lambda m: m.header.frame_id == "imu_link", timeout=2.0)
        assert ri is not None
        cov = np.asarray(ri.orientation_covariance).tolist()
        assert cov[::4] == pytest.approx([3e-4, 3e-4, IMU_YAW_VAR]) and cov[1:4] == [0.0] * 3

        # base/cmd_vel -> rmw_zenoh cmd_vel -> the driver -> sim/device/wheels
        cmd = client_bus.publisher(keys.BASE_CMD_VEL)
        assert cmd.wait_matched(10)
        for _ in range(100):
            cmd.put(Twist(linear_x=0.4, angular_z=0.1))
            if wheels.until(lambda ws: any(w.v == 0.4 for w in ws), timeout=0.1):
                break
        w = wheels.wait_for(lambda w: w.v == 0.4, timeout=1.0)
        assert w is not None and w.w == 0.1

        # the driver goes silent while navigation keeps commanding: after 0.5 s
        # without odometry the base commands zero
        n_cmd = len(ros_cmd)
        husky.send_signal(signal.SIGUSR1)
        t0 = time.monotonic()
        stopped_at = None
        while time.monotonic() - t0 < 5.0:
            cmd.put(Twist(linear_x=0.4, angular_z=0.1))
            if ros_cmd.until(lambda ms: any(m.linear.x == 0.0 for m in ms[n_cmd:]), 0.05):
                stopped_at = time.monotonic() - t0
                break
        assert stopped_at is not None, "the base kept commanding a silent driver"
        assert 0.3 < stopped_at < 2.0, f"stopped {stopped_at:.2f} s after the driver went silent"
        h = health.wait_for(lambda h: h.counters.get("ros2_odom_stale") == 1, timeout=3.0)
        assert h is not None

        # the driver is back: odometry flows, commands pass again
        husky.send_signal(signal.SIGUSR2)
        n_cmd = len(ros_cmd)
        for _ in range(100):
            cmd.put(Twist(linear_x=0.3))
            if ros_cmd.until(lambda ms: any(m.linear.x == 0.3 for m in ms[n_cmd:]), 0.1):
                break
        assert any(m.linear.x == 0.3 for m in ros_cmd[n_cmd:]), "commands did not resume"
    finally:
        stop.set()
        feeder.join()
        spy.close()
        spy_session.close()
    base.send_signal(signal.SIGTERM)
    base.wait(timeout=5)
    text = (tmp_path / "base.log").read_text()
    # (once more at start-up when the driver's first odometry is later than 0.5 s)
    stale = text.rindex("no odometry from the ROS 2 base for 0.50 s (its driver is gone?)")
    assert text.index("odometry from the ROS 2 base is back", stale) > stale, text
