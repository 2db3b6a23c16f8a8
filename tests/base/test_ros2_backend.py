"""The ``ros2`` backend's own logic: the odometry watch, the IMU's conversion and
refusal of bad values, and the zenoh-bridge-ros2dds layout kept beside rmw_zenoh's."""

from __future__ import annotations

import logging
import math
import threading

import msgspec
import pytest

from common.config import ConfigError, decode_section
from common.messages.base import BatteryState, Imu
from common.transport import Bus
from services.base.backends import OdomWatch, Ros2Base, Sinks
from services.base.config import BaseConfig
from services.base.ros2 import msgs as ros
from services.base.ros2.types import twist_of
from services.base.ros2_convert import battery_from_ros, decode_odometry, imu_from_ros
from services.base.sim.husky import HuskySimConfig, command_age_s
from tests.conftest import Record

MS = 1_000_000


def test_odom_watch_times_out_on_the_service_clock() -> None:
    w = OdomWatch(500 * MS)
    assert not w.check(0)  # the timeout runs from the first check
    assert not w.check(500 * MS)
    assert w.check(520 * MS) and w.stale
    w.heard()
    assert not w.check(1000 * MS)  # dated at the check after it arrived
    assert not w.check(1500 * MS)
    assert w.check(1501 * MS)


def test_configs_refuse_bad_ros_names() -> None:
    for bad in ({"ros2_namespace": "husky"}, {"ros2_node": "a/b"}, {"ros2_odom": "od om"}):
        with pytest.raises(ConfigError):
            decode_section({"backend": "ros2", **bad}, BaseConfig, "base")
    cfg = decode_section({"backend": "ros2", "ros2_odom": "/husky/odom"}, BaseConfig, "base")
    assert cfg.ros2_layout == "rmw_zenoh" and cfg.ros2_domain == 0
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert({"domain_id": 300}, HuskySimConfig)


def test_bridge_layout_uses_plain_keys(client_bus: Bus) -> None:
    cfg = BaseConfig(backend="ros2", ros2_layout="bridge", ros2_cmd_vel="t/cmd_vel")
    odom: list[tuple[int, float, float, float, float, float]] = []
    got = threading.Event()

    def on_odom(*a: float) -> None:
        odom.append(a)  # type: ignore[arg-type]
        got.set()

    base = Ros2Base(cfg, client_bus, Sinks(odom=on_odom))
    cmds: list[ros.Twist] = []
    sent = threading.Event()

    def on_cmd(t: ros.Twist) -> None:
        cmds.append(t)
        sent.set()

    client_bus.subscribe_raw("t/cmd_vel", ros.Twist.deserialize, on_cmd)
    base.send(0.3, 0.1, 0)
    assert sent.wait(5.0) and (cmds[-1].linear.x, cmds[-1].angular.z) == (0.3, 0.1)
    o = ros.odometry(7, "odom", "base_link", (1.0, 2.0, 0.0), (0.2, 0.0), [0.0] * 36, [0.0] * 36)
    client_bus.put_raw("odom", o.serialize())
    assert got.wait(5.0) and odom[-1][:3] == (7, 1.0, 2.0)
    assert decode_odometry(o.serialize()).child_frame_id == "base_link"


def _imu(roll: float = 0.1, wx: float = 0.01, tilt_var: float = 3e-4) -> ros.Imu:
    return ros.imu(
        1_000_000_007, "imu_link", (roll, -0.2, 2.5), (wx, 0.02, -0.3), (0.5, -0.1, 9.7), tilt_var,
        yaw_var=0.0076,
    )  # fmt: skip


def test_imu_from_ros() -> None:
    m = imu_from_ros(ros.Imu.deserialize(_imu().serialize()))
    assert (m.stamp_ns, m.frame_id) == (1_000_000_007, "imu_link")
    assert [m.roll, m.pitch, m.yaw] == pytest.approx([0.1, -0.2, 2.5], abs=1e-12)
    assert (m.wx, m.wy, m.wz, m.ax, m.ay, m.az) == (0.01, 0.02, -0.3, 0.5, -0.1, 9.7)
    assert m.tilt_var == pytest.approx(3e-4)
    # the bus message it becomes decodes: its bounds hold
    assert msgspec.msgpack.decode(msgspec.msgpack.encode(m), type=Imu) == m

    r = _imu()
    r.orientation_covariance[4] = 1e-4  # type: ignore[index]
    assert imu_from_ros(r).tilt_var == pytest.approx(2e-4)
    r.orientation_covariance[0] = -1.0  # type: ignore[index] # sensor_msgs: no orientation
    with pytest.raises(ValueError, match="no orientation"):
        imu_from_ros(r)


@pytest.mark.parametrize(
    "bad",
    [
        _imu(roll=math.nan),
        _imu(wx=math.inf),
        _imu(wx=-math.nan),
        _imu(wx=1e3),  # finite, but outside the bus message's bounds
        _imu(tilt_var=math.inf),
    ],
    ids=["nan-orientation", "inf-rate", "nan-rate", "rate-out-of-bounds", "inf-variance"],
)
def test_imu_from_ros_refuses_bad_values(bad: ros.Imu) -> None:
    with pytest.raises(ValueError):
        imu_from_ros(bad)


def test_bridge_layout_imu_drops_bad_messages(
    client_bus: Bus, caplog: pytest.LogCaptureFixture
) -> None:
    cfg = BaseConfig(backend="ros2", ros2_layout="bridge", ros2_imu="t/imu")
    imus: Record[Imu] = Record()
    base = Ros2Base(cfg, client_bus, Sinks(imu=imus.add))
    with caplog.at_level(logging.WARNING):
        client_bus.put_raw("t/imu", _imu(roll=math.nan).serialize())
        client_bus.put_raw("t/imu", _imu(wx=math.inf).serialize())
        client_bus.put_raw("t/imu", b"\x00\x01\x00\x00\x01")  # not CDR
        client_bus.put_raw("t/imu", _imu(roll=0.25).serialize())
        # one publisher, one key: in order, so the good one arrives after the bad ones
        assert imus.until(bool, timeout=5.0)
    assert len(imus) == 1 and imus[0].roll == pytest.approx(0.25)
    assert base.imu_refused == 2 and client_bus.reports()["ros2_imu_refused"] == 2
    assert client_bus.decode_stats.by_key == {"t/imu": 1}
    refused = [r for r in caplog.records if "IMU from the ROS 2 base refused" in r.message]
    assert len(refused) == 1 and "orientation" in refused[0].message, caplog.text


def test_twist_stamped_carries_the_command_stamp_and_frame(client_bus: Bus) -> None:
    """Clearpath's Jazzy platform takes TwistStamped: the stamp is the command's (the
    robot's clock), the frame the configured one."""
    cfg = BaseConfig(
        backend="ros2", ros2_layout="bridge", ros2_cmd_vel="s/cmd_vel",
        ros2_cmd_vel_type="TwistStamped", ros2_cmd_vel_frame="base_link",
    )  # fmt: skip
    base = Ros2Base(cfg, client_bus, Sinks())
    got: Record[ros.TwistStamped] = Record()
    client_bus.subscribe_raw("s/cmd_vel", ros.TwistStamped.deserialize, got.add)
    for _ in range(50):  # until the subscription has reached the base's session
        base.send(0.3, -0.1, 12_000_000_345)
        if got.until(bool, timeout=0.1):
            break
    m = got.wait_for(lambda m: True, timeout=1.0)
    assert m is not None, "no TwistStamped on s/cmd_vel"
    assert (m.twist.linear.x, m.twist.angular.z) == (0.3, -0.1)
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (12, 345)
    assert m.header.frame_id == "base_link"


def test_battery_from_ros() -> None:
    m = battery_from_ros(ros.battery_state(3 * 10**9, 0.4, 25.1, -6.0, 20.0))
    assert (m.stamp_ns, m.percentage, m.voltage, m.current) == (3 * 10**9, 0.4, 25.1, -6.0)
    # no percentage: the charge over the capacity; no voltage: 0
    r = ros.battery_state(0, 0.25, math.nan, math.nan, 20.0)
    r.percentage = math.nan
    m = battery_from_ros(r)
    assert (m.percentage, m.voltage, m.current) == (0.25, 0.0, 0.0)
    r.capacity = math.nan
    with pytest.raises(ValueError, match="percentage is NaN"):
        battery_from_ros(r)
    with pytest.raises(ValueError, match="percentage 85 is outside 0-1"):
        battery_from_ros(ros.battery_state(0, 85.0, 25.0, -1.0, 20.0))


def test_battery_state_reaches_the_bus_and_bad_ones_are_counted(
    client_bus: Bus, caplog: pytest.LogCaptureFixture
) -> None:
    cfg = BaseConfig(backend="ros2", ros2_layout="bridge", ros2_battery="b/bms/state")
    got: Record[BatteryState] = Record()
    base = Ros2Base(cfg, client_bus, Sinks(battery=got.add))
    bad = ros.battery_state(0, 85.0, 25.0, -1.0, 20.0)
    good = ros.battery_state(7 * 10**9, 0.55, 25.0, -5.0, 20.0)
    with caplog.at_level(logging.WARNING):
        for _ in range(50):  # until the subscription has reached the session
            client_bus.put_raw("b/bms/state", bad.serialize())
            client_bus.put_raw("b/bms/state", good.serialize())
            if got.until(bool, timeout=0.1):
                break
    m = got.wait_for(lambda m: True, timeout=1.0)
    assert m is not None and m.percentage == pytest.approx(0.55)
    assert client_bus.reports()["ros2_battery_refused"] >= 1
    refused = [
        r for r in caplog.records if "battery state from the ROS 2 base refused" in r.message
    ]
    assert len(refused) == 1 and "outside 0-1" in refused[0].message, caplog.text
    assert base.imu_refused == 0


def test_emulated_clearpath_driver_ages_stamped_commands() -> None:
    """diff_drive_controller's rule, as the Husky emulator plays it: a zero stamp is
    now, otherwise the age by the driver's clock."""
    stamped = ros.twist_stamped(0.2, 0.0, 9_500_000_000, "base_link")
    assert command_age_s(stamped, 10_000_000_000) == pytest.approx(0.5)
    assert command_age_s(ros.twist_stamped(0.2, 0.0, 0, "base_link"), 10**12) == 0.0
    assert twist_of(stamped) == ros.twist(0.2, 0.0) == twist_of(ros.twist(0.2, 0.0))
    with pytest.raises(ConfigError):
        decode_section({"backend": "ros2", "ros2_cmd_vel_type": "Twist2"}, BaseConfig, "base")


def _odom(x: float = 1.0, v: float = 0.2, yaw: float = 0.5) -> ros.Odometry:
    cov = [0.0] * 36
    return ros.odometry(3 * MS, "odom", "base_link", (x, 2.0, yaw), (v, 0.1), cov, cov)


def test_odometry_with_a_value_that_is_not_finite_is_refused(
    client_bus: Bus, caplog: pytest.LogCaptureFixture
) -> None:
    cfg = BaseConfig(backend="ros2", ros2_layout="bridge", ros2_odom="t/odom")
    odoms: Record[tuple[float, ...]] = Record()
    Ros2Base(cfg, client_bus, Sinks(odom=lambda *o: odoms.add(o)))
    with caplog.at_level(logging.WARNING):
        client_bus.put_raw("t/odom", _odom(x=math.nan).serialize())
        client_bus.put_raw("t/odom", _odom(v=math.inf).serialize())
        client_bus.put_raw("t/odom", _odom(x=1.5).serialize())
        # one publisher, one key: in order, so the good one arrives after the bad ones
        assert odoms.until(bool, timeout=5.0)
    assert len(odoms) == 1 and odoms[0][1:] == pytest.approx((1.5, 2.0, 0.5, 0.2, 0.1))
    assert client_bus.reports()["ros2_odom_refused"] == 2
    refused = [r for r in caplog.records if "odometry from the ROS 2 base refused" in r.message]
    assert len(refused) == 1 and "pose.position.x" in refused[0].message, caplog.text
