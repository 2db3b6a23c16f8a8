"""A simulated Husky ROS 2 driver over rmw_zenoh: the ``ros2`` backend of the base
service drives it as it drives the real Husky, and it drives the simulator's base.

``python -m services.base.sim.husky --manifest M`` (config ``[services.husky-sim]``).
As a ROS 2 node (``husky_node`` by default) on the Zenoh network it

- subscribes ``cmd_vel`` (geometry_msgs/Twist, or TwistStamped as Clearpath's Jazzy
  platform takes it: ``cmd_vel_type``) and forwards each command to the
  simulator as a SimWheelCommand on ``sim/device/wheels``;
- publishes ``odom`` (nav_msgs/Odometry) at the encoder rate, one per
  ``sim/device/encoders`` message: pose integrated from the encoder twist (the
  base service's own dead reckoning), twist = the encoder twist, covariances as
  Clearpath's husky_control configures diff_drive_controller;
- publishes ``scan`` (sensor_msgs/LaserScan) from ``sim/device/lidar``;
- publishes ``imu/data`` (sensor_msgs/Imu) from ``sim/device/imu``, as the Husky's
  UM7 driver does: roll and pitch variance the simulator's ``tilt_var``, yaw
  variance ``yaw_var`` (a magnetometer heading beside the motors);
- publishes ``battery_state`` (sensor_msgs/BatteryState) from
  ``sim/device/battery``, as Clearpath's battery node does on
  ``platform/bms/state``: the charge as a fraction and in Ah of the robot
  description's pack.

Stamps are on the service clock (the sim clock in a simulated deployment).
The fault hook (``HuskySim.fault``; SIGUSR1 in the process, SIGUSR2 to undo) makes it
silent, as if the driver were gone: nothing is published and commands are not
forwarded.
"""

from __future__ import annotations

import math
import signal
import threading
from typing import Annotated

import msgspec
import numpy as np

from common import keys
from common.messages.base import BatteryState, Imu, LaserScan
from common.messages.core import BASE_FRAME, ODOM_FRAME, NonNegative, Positive
from common.messages.sim import SimEncoders, SimWheelCommand
from common.service import Context, run
from services.base.drive import OdometryIntegrator
from services.base.refusals import Refusals
from services.base.ros2 import msgs as ros
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import (
    BATTERY_STATE,
    CMD_VEL_TYPES,
    IMU,
    LASER_SCAN,
    ODOMETRY,
    CmdVelType,
    twist_of,
)
from services.base.ros2.wire import NAME_PATTERN, NAMESPACE_PATTERN, SENSOR_QOS, TOPIC_PATTERN

Cov6 = tuple[NonNegative, NonNegative, NonNegative, NonNegative, NonNegative, NonNegative]
Topic = Annotated[str, msgspec.Meta(pattern=TOPIC_PATTERN)]
# husky_control/config/control.yaml (husky_velocity_controller): x y z roll pitch yaw
HUSKY_COVARIANCE: Cov6 = (0.001, 0.001, 0.001, 0.001, 0.001, 0.03)
# The UM7's yaw is its magnetometer's, not to be trusted beside the motors: (5 deg)^2.
IMU_YAW_VAR = math.radians(5.0) ** 2
# Angular velocity and specific force variances are small constants, per axis: the
# simulator's IMU message states none. (0.02 rad/s)^2 covers services/sim/imu.py's
# gyro (0.01 rad/s white, 0.005 rad/s bias); (0.1 m/s^2)^2 a UM7-class accelerometer.
IMU_GYRO_VAR = 4e-4
IMU_ACCEL_VAR = 1e-2


class HuskySimConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The simulated driver as a ROS 2 node. ``cmd_vel_type = "TwistStamped"`` with
    ``namespace = "/a200_0000"``, ``odom = "platform/odom"``, ``scan =
    "sensors/lidar2d_0/scan"``, ``imu = "sensors/imu_0/data"`` and ``battery =
    "platform/bms/state"`` plays Clearpath's ROS 2 Jazzy platform."""

    domain_id: Annotated[int, msgspec.Meta(ge=0, le=232)] = 0
    """The ROS 2 domain."""
    namespace: Annotated[str, msgspec.Meta(pattern=NAMESPACE_PATTERN)] = "/"
    """The namespace the topics are resolved against."""
    node_name: Annotated[str, msgspec.Meta(pattern=NAME_PATTERN)] = "husky_node"
    """The node's name."""
    cmd_vel: Topic = "cmd_vel"
    """The velocity command topic (the base service's ``ros2_cmd_vel``)."""
    cmd_vel_type: CmdVelType = "Twist"
    """The velocity command's message type."""
    odom: Topic = "odom"
    """The odometry topic (the base service's ``ros2_odom``)."""
    scan: Topic = "scan"
    """The 2D lidar's topic (the base service's ``ros2_scan``)."""
    imu: Topic = "imu/data"
    """The IMU's topic (the base service's ``ros2_imu``)."""
    battery: Topic = "battery_state"
    """The battery's topic (the base service's ``ros2_battery``)."""
    odom_frame: str = ODOM_FRAME
    """The odometry's frame."""
    base_frame: str = BASE_FRAME
    """The odometry's child frame."""
    pose_covariance: Cov6 = HUSKY_COVARIANCE
    """The diagonal (x, y, z, roll, pitch, yaw) of the pose covariance the odometry
    carries (husky_control's)."""
    twist_covariance: Cov6 = HUSKY_COVARIANCE
    """The diagonal (x, y, z, roll, pitch, yaw) of the twist covariance the odometry
    carries (husky_control's)."""
    yaw_var: NonNegative = IMU_YAW_VAR
    """The IMU's yaw variance (rad²)."""
    cmd_vel_timeout_s: Positive = 0.5
    """A stamped command older than this by the node's own clock is refused, and a zero
    stamp is taken as now (diff_drive_controller's ``cmd_vel_timeout``: its default,
    0.5 s, here; Clearpath's husky_control sets 0.25 s, the figure docs/devices.md
    gives for the wheels' stop)."""


def covariance(diagonal: Cov6) -> list[float]:
    """A row-major 6x6 covariance with ``diagonal`` on its diagonal."""
    return [float(v) for v in np.diag(np.asarray(diagonal, dtype=np.float64)).ravel()]


def scan_to_ros(scan: LaserScan, stamp_ns: int) -> ros.LaserScan:
    """The simulator's scan as sensor_msgs/LaserScan (``inf``: no return, REP-117)."""
    return ros.laser_scan(
        stamp_ns,
        scan.frame_id,
        (scan.angle_min, scan.angle_max, scan.angle_increment),
        (scan.range_min, scan.range_max),
        scan.ranges.numpy().astype(np.float32).tolist(),
    )


def imu_to_ros(m: Imu, stamp_ns: int, yaw_var: float) -> ros.Imu:
    """The simulator's IMU as sensor_msgs/Imu, covariances diagonal (see the constants)."""
    return ros.imu(
        stamp_ns,
        m.frame_id,
        (m.roll, m.pitch, m.yaw),
        (m.wx, m.wy, m.wz),
        (m.ax, m.ay, m.az),
        m.tilt_var,
        yaw_var=yaw_var,
        angular_velocity_var=IMU_GYRO_VAR,
        linear_acceleration_var=IMU_ACCEL_VAR,
    )


def command_age_s(msg: ros.TwistStamped, now_ns: int) -> float:
    """How old a stamped command is by the driver's clock; a zero stamp is taken as
    now, as diff_drive_controller takes it."""
    stamp_ns = ros.ns_of_time(msg.header.stamp)
    return 0.0 if stamp_ns == 0 else (now_ns - stamp_ns) * 1e-9


class HuskySim:
    def __init__(self, ctx: Context, cfg: HuskySimConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        self.silent = False
        # commands that were not finite, or stamped too long ago
        self.commands = Refusals(ctx.bus, "commands_refused", "cmd_vel")
        self._lock = threading.Lock()
        self._odom = OdometryIntegrator()
        self._pose_cov = covariance(cfg.pose_covariance)
        self._twist_cov = covariance(cfg.twist_covariance)
        self.node = Ros2Node(ctx.bus.session, cfg.node_name, cfg.namespace, cfg.domain_id)
        self._odom_pub = self.node.publisher(cfg.odom, ODOMETRY)
        self._scan_pub = self.node.publisher(cfg.scan, LASER_SCAN, qos=SENSOR_QOS)
        self._imu_pub = self.node.publisher(cfg.imu, IMU, qos=SENSOR_QOS)
        self._battery_pub = self.node.publisher(cfg.battery, BATTERY_STATE, qos=SENSOR_QOS)
        self._wheels = ctx.bus.publisher(keys.SIM_WHEELS)
        ctx.bus.report("ros2_dropped", lambda: self.node.dropped_total)
        self.node.subscribe(cfg.cmd_vel, CMD_VEL_TYPES[cfg.cmd_vel_type], self._on_cmd)
        ctx.bus.subscribe(keys.SIM_ENCODERS, self._on_encoders)
        ctx.bus.subscribe(keys.SIM_LIDAR, self._on_lidar)
        ctx.bus.subscribe(keys.SIM_IMU, self._on_imu)
        ctx.bus.subscribe(keys.SIM_BATTERY, self._on_battery)

    def fault(self, silent: bool) -> None:
        """Go silent (the ROS 2 driver gone) or come back."""
        if silent != self.silent:
            self.ctx.log.warning("fault: driver %s", "silent" if silent else "back")
        self.silent = silent

    def _on_cmd(self, msg: ros.Twist | ros.TwistStamped) -> None:
        if self.silent:
            return
        now_ns = self.ctx.clock.now_ns()
        t = twist_of(msg)
        v, w = t.linear.x, t.angular.z
        problem = ""
        if not (math.isfinite(v) and math.isfinite(w)):
            problem = f"v={v!r} w={w!r} is not finite"
        elif isinstance(msg, ros.TwistStamped):
            age_s = command_age_s(msg, now_ns)
            if age_s > self.cfg.cmd_vel_timeout_s:
                problem = (
                    f"stamped {age_s:.3f} s ago (cmd_vel_timeout {self.cfg.cmd_vel_timeout_s} s)"
                )
        if problem:
            self.commands.refuse(problem)
            return
        self._wheels.put(SimWheelCommand(stamp_ns=now_ns, v=v, w=w))

    def _on_encoders(self, m: SimEncoders) -> None:
        with self._lock:
            self._odom.update(m.v, m.w, m.stamp_ns)
            x, y, yaw = self._odom.x, self._odom.y, self._odom.yaw
        if self.silent:
            return
        self._odom_pub.put(
            ros.odometry(
                self.ctx.clock.now_ns(),
                self.cfg.odom_frame,
                self.cfg.base_frame,
                (x, y, yaw),
                (m.v, m.w),
                self._pose_cov,
                self._twist_cov,
            )
        )

    def _on_lidar(self, scan: LaserScan) -> None:
        if not self.silent:
            self._scan_pub.put(scan_to_ros(scan, self.ctx.clock.now_ns()))

    def _on_imu(self, m: Imu) -> None:
        if not self.silent:
            self._imu_pub.put(imu_to_ros(m, self.ctx.clock.now_ns(), self.cfg.yaw_var))

    def _on_battery(self, m: BatteryState) -> None:
        if not self.silent:
            pct, now = m.percentage, self.ctx.clock.now_ns()
            spec = self.ctx.robot.battery
            ah = spec.capacity_wh / spec.voltage_v
            self._battery_pub.put(ros.battery_state(now, pct, m.voltage, m.current, ah))

    def run(self, stop: threading.Event) -> None:
        stop.wait()
        self.node.close()


def build(ctx: Context, cfg: HuskySimConfig) -> HuskySim:
    sim = HuskySim(ctx, cfg)
    # build() runs on the main thread, where Python handles signals
    signal.signal(signal.SIGUSR1, lambda *_: sim.fault(True))
    signal.signal(signal.SIGUSR2, lambda *_: sim.fault(False))
    return sim


if __name__ == "__main__":
    run("husky-sim", HuskySimConfig, build)
