"""Base backends: what drives the wheels and where odometry, the IMU, the 2D lidar and
the battery's state come from. ``BACKENDS`` maps the config's ``backend`` to a class."""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections.abc import Callable
from typing import Any, Protocol

from common import keys
from common.messages.base import BatteryState, Imu, LaserScan
from common.messages.sim import SimWheelCommand
from common.transport import Bus
from services.base.config import BaseConfig
from services.base.refusals import Refusals
from services.base.ros2 import msgs as ros
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import BATTERY_STATE, CMD_VEL_TYPES, IMU, LASER_SCAN, ODOMETRY
from services.base.ros2.wire import SENSOR_QOS
from services.base.ros2_convert import (
    Odom,
    battery_from_ros,
    decode_battery,
    decode_imu,
    decode_odometry,
    decode_scan,
    imu_from_ros,
    odom_from_ros,
    scan_from_ros,
)

# (stamp_ns, v, w) from the wheel encoders
EncoderCallback = Callable[[int, float, float], None]
# a ready odometry pose from the base itself: (stamp_ns, x, y, yaw, v, w)
OdomCallback = Callable[[int, float, float, float, float, float], None]


def _ignore(*_: Any) -> None:
    pass


@dataclasses.dataclass(frozen=True)
class Sinks:
    """Where a backend hands what the base senses (each ignored unless given)."""

    encoders: EncoderCallback = _ignore
    odom: OdomCallback = _ignore
    scan: Callable[[LaserScan], None] = _ignore
    imu: Callable[[Imu], None] = _ignore
    battery: Callable[[BatteryState], None] = _ignore


class Drive(Protocol):
    def send(self, v: float, w: float, stamp_ns: int) -> None:
        """Drive the wheels at body velocities v (m/s), w (rad/s)."""
        ...


class SimBase:
    """The simulator's Husky: wheel commands out; encoders, lidar, IMU and battery in."""

    def __init__(self, cfg: BaseConfig, bus: Bus, sinks: Sinks) -> None:
        self._wheels = bus.publisher(keys.SIM_WHEELS)
        bus.subscribe(keys.SIM_ENCODERS, lambda m: sinks.encoders(m.stamp_ns, m.v, m.w))
        bus.subscribe(keys.SIM_LIDAR, sinks.scan)
        bus.subscribe(keys.SIM_IMU, sinks.imu)
        bus.subscribe(keys.SIM_BATTERY, sinks.battery)

    def send(self, v: float, w: float, stamp_ns: int) -> None:
        self._wheels.put(SimWheelCommand(stamp_ns=stamp_ns, v=v, w=w))


class OdomWatch:
    """Whether a ROS 2 base's odometry has gone quiet, timed on the service clock: an
    arrival is noted from Zenoh's thread (``heard``) and dated at the next wheel
    command (``check``, called at the control rate), so the two clocks of the base and
    of its driver never meet. Until the first arrival the timeout runs from the first
    check."""

    def __init__(self, timeout_ns: int) -> None:
        self.timeout_ns = timeout_ns
        self.stale = False
        self._heard = False
        self._last_ns: int | None = None
        self._lock = threading.Lock()

    def heard(self) -> None:
        with self._lock:
            self._heard = True

    def check(self, now_ns: int) -> bool:
        """Whether the odometry is stale now; updates ``stale``."""
        with self._lock:
            if self._heard or self._last_ns is None:
                self._last_ns = now_ns
                self._heard = False
            self.stale = now_ns - self._last_ns > self.timeout_ns
            return self.stale


class Ros2Base:
    """Any ROS 2 base: Twist or TwistStamped out; Odometry, LaserScan, Imu and
    BatteryState in; CDR payloads. Through rmw_zenoh (``ros2_layout = "rmw_zenoh"``,
    :mod:`services.base.ros2`): this service is a ROS 2 node on the Zenoh network; through
    zenoh-bridge-ros2dds (``"bridge"``): the bridge maps ROS topic ``/cmd_vel`` to the
    Zenoh key ``cmd_vel`` (and so on).

    With no odometry for ``ros2_odom_timeout_s`` the driver is taken for gone: the
    wheels are commanded to zero (so a driver that returns does not resume an old
    command) and one log line says so, another when odometry is back; the health
    counter ``ros2_odom_stale`` is 1 meanwhile.

    An Odometry, an Imu or a BatteryState with a value that is not finite or out of
    the bus message's bounds is dropped: counted in the health counters
    ``ros2_odom_refused``, ``ros2_imu_refused`` and ``ros2_battery_refused``, the first
    one logged (payloads that are not CDR at
    all are dropped and counted as for odometry)."""

    def __init__(self, cfg: BaseConfig, bus: Bus, sinks: Sinks) -> None:
        self._log = logging.getLogger(bus.name)
        self._timeout_s = cfg.ros2_odom_timeout_s
        self._watch = OdomWatch(int(cfg.ros2_odom_timeout_s * 1e9))
        bus.report("ros2_odom_stale", lambda: int(self._watch.stale))

        odoms = Refusals(bus, "ros2_odom_refused", "odometry from the ROS 2 base")

        def heard(o: Odom) -> None:
            # heard only when it passes: a driver sending only refused odometry is gone
            self._watch.heard()
            sinks.odom(*o)

        def odom(m: ros.Odometry) -> None:
            odoms.passed(odom_from_ros, m, heard)

        def scan(m: ros.LaserScan) -> None:
            sinks.scan(scan_from_ros(m))

        imus = Refusals(bus, "ros2_imu_refused", "IMU from the ROS 2 base")
        batteries = Refusals(bus, "ros2_battery_refused", "battery state from the ROS 2 base")

        def imu(m: ros.Imu) -> None:
            imus.passed(imu_from_ros, m, sinks.imu)

        def battery(m: ros.BatteryState) -> None:
            batteries.passed(battery_from_ros, m, sinks.battery)

        self._imus = imus
        self._cmd_type = CMD_VEL_TYPES[cfg.ros2_cmd_vel_type]
        self._frame = cfg.ros2_cmd_vel_frame
        self._put: Callable[[ros.Twist | ros.TwistStamped], None]
        if cfg.ros2_layout == "bridge":
            key = cfg.ros2_cmd_vel
            bus.subscribe_raw(cfg.ros2_odom, decode_odometry, odom)
            bus.subscribe_raw(cfg.ros2_scan, decode_scan, scan)
            bus.subscribe_raw(cfg.ros2_imu, decode_imu, imu)
            bus.subscribe_raw(cfg.ros2_battery, decode_battery, battery)
            self._put = lambda t: bus.put_raw(key, t.serialize())
        else:
            node = Ros2Node(bus.session, cfg.ros2_node, cfg.ros2_namespace, cfg.ros2_domain)
            bus.report("ros2_dropped", lambda: node.dropped_total)
            self._put = node.publisher(cfg.ros2_cmd_vel, self._cmd_type).put
            node.subscribe(cfg.ros2_odom, ODOMETRY, odom)
            node.subscribe(cfg.ros2_scan, LASER_SCAN, scan, qos=SENSOR_QOS)
            node.subscribe(cfg.ros2_imu, IMU, imu, qos=SENSOR_QOS)
            # Clearpath's battery node publishes with the sensor-data QoS
            node.subscribe(cfg.ros2_battery, BATTERY_STATE, battery, qos=SENSOR_QOS)
            self.node = node

    @property
    def imu_refused(self) -> int:
        return self._imus.count

    def send(self, v: float, w: float, stamp_ns: int) -> None:
        if not (math.isfinite(v) and math.isfinite(w)):
            v = w = 0.0
        was = self._watch.stale
        if self._watch.check(stamp_ns):
            if not was:
                self._log.warning(
                    "no odometry from the ROS 2 base for %.2f s (its driver is gone?): "
                    "wheels stopped until it is back",
                    self._timeout_s,
                )
            v = w = 0.0
        elif was:
            self._log.info("odometry from the ROS 2 base is back: commands pass again")
        if self._cmd_type.cls is ros.TwistStamped:
            self._put(ros.twist_stamped(v, w, stamp_ns, self._frame))
        else:
            self._put(ros.twist(v, w))


BACKENDS: dict[str, type[SimBase] | type[Ros2Base]] = {"sim": SimBase, "ros2": Ros2Base}
