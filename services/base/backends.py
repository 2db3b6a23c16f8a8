"""Base backends: what drives the wheels and where odometry, the IMU and the 2D lidar
come from. ``BACKENDS`` maps the config's ``backend`` to a class."""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from typing import Protocol

import msgspec
import numpy as np

from common import keys
from common.messages.base import Imu, LaserScan
from common.messages.core import Array
from common.messages.sim import SimWheelCommand
from common.ros2 import msgs as ros
from common.ros2.node import Ros2Node
from common.ros2.types import CMD_VEL_TYPES, IMU, LASER_SCAN, ODOMETRY
from common.ros2.wire import SENSOR_QOS
from common.transport import Bus
from services.base.config import BaseConfig

# (stamp_ns, v, w) from the wheel encoders
EncoderCallback = Callable[[int, float, float], None]
# a ready odometry pose from the base itself: (stamp_ns, x, y, yaw, v, w)
OdomCallback = Callable[[int, float, float, float, float, float], None]


class Drive(Protocol):
    def send(self, v: float, w: float, stamp_ns: int) -> None:
        """Drive the wheels at body velocities v (m/s), w (rad/s)."""
        ...


class SimBase:
    """The simulator's Husky: wheel commands out, encoders and lidar in."""

    def __init__(
        self,
        cfg: BaseConfig,
        bus: Bus,
        on_encoders: EncoderCallback,
        on_odom: OdomCallback,
        on_scan: Callable[[LaserScan], None],
        on_imu: Callable[[Imu], None],
    ) -> None:
        self._wheels = bus.publisher(keys.SIM_WHEELS)
        bus.subscribe(keys.SIM_ENCODERS, lambda m: on_encoders(m.stamp_ns, m.v, m.w))
        bus.subscribe(keys.SIM_LIDAR, on_scan)
        bus.subscribe(keys.SIM_IMU, on_imu)

    def send(self, v: float, w: float, stamp_ns: int) -> None:
        self._wheels.put(SimWheelCommand(stamp_ns=stamp_ns, v=v, w=w))


def decode_odometry(data: bytes) -> ros.Odometry:
    return ros.Odometry.deserialize(data)


def decode_scan(data: bytes) -> ros.LaserScan:
    return ros.LaserScan.deserialize(data)


def decode_imu(data: bytes) -> ros.Imu:
    return ros.Imu.deserialize(data)


def imu_from_ros(m: ros.Imu) -> Imu:
    """The bus message of a sensor_msgs/Imu: orientation as ZYX Euler angles,
    ``tilt_var`` the mean of the roll and pitch variances the driver states. Raises
    ValueError naming the field when the message holds no orientation (sensor_msgs:
    a first covariance element of -1; navigation would take its zero quaternion for a
    level robot), or a value is not finite or is outside the bus message's bounds
    (which every subscriber would refuse on decode)."""
    q = m.orientation
    if not all(math.isfinite(c) for c in (q.x, q.y, q.z, q.w)):
        raise ValueError(f"orientation ({q.x}, {q.y}, {q.z}, {q.w}) is not finite")
    var_roll, var_pitch = (float(v) for v in np.asarray(m.orientation_covariance)[[0, 4]])
    if var_roll < 0.0:
        raise ValueError("orientation_covariance[0] < 0: the IMU states no orientation")
    roll, pitch, yaw = ros.euler_of(q)
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
    """Any ROS 2 base: Twist or TwistStamped out, Odometry, LaserScan and Imu in, CDR
    payloads. Through
    rmw_zenoh (``ros2_layout = "rmw_zenoh"``, :mod:`common.ros2`): this service is a
    ROS 2 node on the Zenoh network; through zenoh-bridge-ros2dds (``"bridge"``): the
    bridge maps ROS topic ``/cmd_vel`` to the Zenoh key ``cmd_vel`` (and so on).

    With no odometry for ``ros2_odom_timeout_s`` the driver is taken for gone: the
    wheels are commanded to zero (so a driver that returns does not resume an old
    command) and one log line says so, another when odometry is back; the health
    counter ``ros2_odom_stale`` is 1 meanwhile.

    An Imu with a value that is not finite or out of the bus message's bounds is
    dropped: counted in the health counter ``ros2_imu_refused``, the first one logged
    (payloads that are not CDR at all are dropped and counted as for odometry)."""

    def __init__(
        self,
        cfg: BaseConfig,
        bus: Bus,
        on_encoders: EncoderCallback,
        on_odom: OdomCallback,
        on_scan: Callable[[LaserScan], None],
        on_imu: Callable[[Imu], None],
    ) -> None:
        self._log = logging.getLogger(bus.name)
        self._timeout_s = cfg.ros2_odom_timeout_s
        self._watch = OdomWatch(int(cfg.ros2_odom_timeout_s * 1e9))
        bus.report("ros2_odom_stale", lambda: int(self._watch.stale))

        def odom(m: ros.Odometry) -> None:
            self._watch.heard()
            p, t = m.pose.pose, m.twist.twist
            on_odom(
                ros.ns_of_time(m.header.stamp),
                p.position.x,
                p.position.y,
                ros.yaw_of(p.orientation),
                t.linear.x,
                t.angular.z,
            )

        def scan(m: ros.LaserScan) -> None:
            on_scan(scan_from_ros(m))

        self.imu_refused = 0
        self._imu_lock = threading.Lock()
        bus.report("ros2_imu_refused", lambda: self.imu_refused)

        def imu(m: ros.Imu) -> None:
            try:
                msg = imu_from_ros(m)
            except ValueError as exc:
                with self._imu_lock:
                    self.imu_refused += 1
                    first = self.imu_refused == 1
                if first:
                    self._log.warning(
                        "IMU from the ROS 2 base refused (later ones only counted): %s", exc
                    )
                return
            on_imu(msg)

        self._cmd_type = CMD_VEL_TYPES[cfg.ros2_cmd_vel_type]
        self._frame = cfg.ros2_cmd_vel_frame
        self._put: Callable[[ros.Twist | ros.TwistStamped], None]
        if cfg.ros2_layout == "bridge":
            key = cfg.ros2_cmd_vel
            bus.subscribe_raw(cfg.ros2_odom, decode_odometry, odom)
            bus.subscribe_raw(cfg.ros2_scan, decode_scan, scan)
            bus.subscribe_raw(cfg.ros2_imu, decode_imu, imu)
            self._put = lambda t: bus.put_raw(key, t.serialize())
        else:
            node = Ros2Node(bus.session, cfg.ros2_node, cfg.ros2_namespace, cfg.ros2_domain)
            bus.report("ros2_dropped", lambda: node.dropped_total)
            self._put = node.publisher(cfg.ros2_cmd_vel, self._cmd_type).put
            node.subscribe(cfg.ros2_odom, ODOMETRY, odom)
            node.subscribe(cfg.ros2_scan, LASER_SCAN, scan, qos=SENSOR_QOS)
            node.subscribe(cfg.ros2_imu, IMU, imu, qos=SENSOR_QOS)
            self.node = node

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
