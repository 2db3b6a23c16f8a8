from typing import Annotated, Literal

import msgspec

from common.messages.core import BASE_FRAME, NonNegative, Positive
from services.base.ros2.types import CmdVelType
from services.base.ros2.wire import NAME_PATTERN, NAMESPACE_PATTERN, TOPIC_PATTERN

Topic = Annotated[str, msgspec.Meta(pattern=TOPIC_PATTERN)]


class BaseConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The mobile base; the speed limits it clips commands to are the robot
    description's ``[limits]`` (:mod:`common.robot`)."""

    backend: Literal["sim", "ros2"]  # required: a robot must never drive a simulated base
    """``ros2`` (any ROS 2 base, the Husky's own driver included) or ``sim`` (the
    simulator's base)."""
    watchdog_s: Positive = 0.25
    """No velocity command for this long stops the wheels (the Husky driver's own
    ``cmd_vel_timeout``): navigation commands at 20 Hz, so 0.25 s is five missed
    commands, and a robot at 0.5 m/s whose navigation dies stands within 0.2 m (0.125 m
    to the trip, about 0.08 m of drivetrain lag)."""
    commander: str = "nav"
    """The service whose commands are obeyed; when its liveliness token goes, the wheels
    stop at once, and its commands still in flight are void until a commander's token is
    back."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=200)] = 50.0
    """How often the wheels are commanded and the base status published (Hz); odometry
    goes out as the encoders or the driver send it."""
    var_v: NonNegative = 1e-4
    """The odometry's stated speed variance, (m/s)²."""
    var_w: NonNegative = 1e-4
    """The odometry's stated turn-rate variance from the encoders' noise, (rad/s)²; the
    skid-steer's scrub comes on top (``turn_slip_sd``)."""
    turn_slip_sd: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.1
    """The skid-steer's scrub, which the encoders cannot see, as a fraction of the turn
    rate, 1 sigma: (``turn_slip_sd`` × rate)² is added to ``var_w`` (the body yaws at
    0.93 of the wheel-implied rate on firm soil and less on loose). A constant variance
    sized for 0.6 rad/s turns would call a 0.005 rad/s heading trim 60 times noisier
    than it is, and the moving GNSS compass would then pull the settled heading by its
    own error (0.6 deg per fix) during every trim."""
    ros2_cmd_vel: Topic = "cmd_vel"
    """The ROS 2 topic the velocity command goes out on (deploy/robot.toml: Clearpath's
    Jazzy names, docs/devices.md)."""
    ros2_cmd_vel_type: CmdVelType = "Twist"
    """The command's type: ``Twist`` (geometry_msgs/msg/Twist: ROS 2 Humble's Clearpath
    stack, most drivers) or ``TwistStamped`` (Clearpath's ROS 2 Jazzy platform), stamped
    on the service clock. A type the driver does not take is a different rmw_zenoh key,
    so it would never hear us: ``ros2 topic info -v <cmd_vel>`` on the robot names the
    type it subscribes."""
    ros2_cmd_vel_frame: str = BASE_FRAME
    """The frame a ``TwistStamped`` command is stamped with."""
    ros2_odom: Topic = "odom"
    """The ROS 2 topic Odometry comes in on."""
    ros2_scan: Topic = "scan"
    """The ROS 2 topic LaserScan comes in on."""
    ros2_imu: Topic = "imu/data"
    """The ROS 2 topic sensor_msgs/Imu comes in on (the Husky's UM7 driver publishes
    ``imu/data``)."""
    ros2_battery: Topic = "battery_state"
    """The ROS 2 topic sensor_msgs/BatteryState comes in on (Clearpath's Jazzy platform
    publishes ``platform/bms/state``)."""
    ros2_layout: Literal["rmw_zenoh", "bridge"] = "rmw_zenoh"
    """How ROS 2 is reached: ``rmw_zenoh`` (the ROS 2 nodes run
    ``RMW_IMPLEMENTATION=rmw_zenoh_cpp``, rmw_zenoh_cpp 0.2.4 or later on Jazzy, and
    share this Zenoh network; docs/devices.md) or ``bridge`` (zenoh-bridge-ros2dds: ROS
    topic ``/cmd_vel`` is the plain Zenoh key ``cmd_vel``)."""
    ros2_domain: Annotated[int, msgspec.Meta(ge=0, le=232)] = 0
    """``rmw_zenoh`` only: ``ROS_DOMAIN_ID`` (0-232: what DDS port arithmetic allows,
    kept by rmw_zenoh)."""
    ros2_namespace: Annotated[str, msgspec.Meta(pattern=NAMESPACE_PATTERN)] = "/"
    """``rmw_zenoh`` only: the namespace topic names resolve in."""
    ros2_node: Annotated[str, msgspec.Meta(pattern=NAME_PATTERN)] = "phenorover_base"
    """``rmw_zenoh`` only: the node name ``ros2 node list`` shows."""
    ros2_odom_timeout_s: Positive = 0.5
    """No odometry from the ROS 2 base for this long (its driver gone, or the link to
    it): the base commands zero until odometry is back, and says so once each way."""
