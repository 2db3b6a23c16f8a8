"""The ``ros2`` backend's own logic: the odometry watch, and the zenoh-bridge-ros2dds
layout kept beside rmw_zenoh's."""

from __future__ import annotations

import threading

import msgspec
import pytest

from common.config import ConfigError, decode_section
from common.ros2 import msgs as ros
from common.transport import Bus
from services.base.backends import OdomWatch, Ros2Base, decode_odometry
from services.base.config import BaseConfig
from services.base.husky_sim import HuskySimConfig

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

    base = Ros2Base(cfg, client_bus, lambda *_: None, on_odom, lambda _: None)
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
