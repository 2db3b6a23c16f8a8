from typing import Annotated, Literal

import msgspec

from common.messages.core import BASE_FRAME, Positive
from common.ros2.types import CmdVelType
from common.ros2.wire import NAME_PATTERN, NAMESPACE_PATTERN, TOPIC_PATTERN

Topic = Annotated[str, msgspec.Meta(pattern=TOPIC_PATTERN)]


class BaseConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The mobile base; the speed limits it clips commands to are the robot
    description's ``[limits]`` (:mod:`common.robot`). ``watchdog_s``: with no velocity
    command for this long the wheels are stopped: navigation commands at 20 Hz, so
    0.25 s is five missed commands, and a robot at 0.5 m/s whose navigation dies stands
    within 0.2 m (0.125 m to the trip, about 0.08 m of drivetrain lag).

    ``backend``: ``sim`` (the simulator's base) or ``ros2`` (any ROS 2 base, the Husky's
    own driver included: Twist out on ``ros2_cmd_vel``, Odometry in on ``ros2_odom``,
    LaserScan in on ``ros2_scan``, sensor_msgs/Imu in on ``ros2_imu``: the Husky's UM7
    driver publishes ``imu/data``; sensor_msgs/BatteryState in on ``ros2_battery``:
    Clearpath's Jazzy platform publishes ``platform/bms/state``). ``ros2_layout`` says
    how ROS 2 is reached: ``rmw_zenoh`` (the ROS 2 nodes run
    ``RMW_IMPLEMENTATION=rmw_zenoh_cpp``, Jazzy's rmw_zenoh 0.2.x, and share this Zenoh
    network; topic names resolve against ``ros2_namespace``, the base appears in ``ros2
    node list`` as ``ros2_node`` in domain ``ros2_domain``) or ``bridge``
    (zenoh-bridge-ros2dds maps ROS topic ``/cmd_vel`` to the plain Zenoh key
    ``cmd_vel``). ``ros2_odom_timeout_s``: with no odometry from the ROS 2 base for this
    long (its driver is gone, or the link to it), the base commands zero until odometry
    returns, and says so in its log.

    ``ros2_cmd_vel_type``: ``Twist`` (geometry_msgs/msg/Twist: ROS 2 Humble's
    Clearpath stack, most drivers) or ``TwistStamped`` (Clearpath's ROS 2 Jazzy
    platform), stamped on the service clock with frame ``ros2_cmd_vel_frame``. A type
    the driver does not take is a different rmw_zenoh key, so it would never hear us:
    ``ros2 topic info -v <cmd_vel>`` on the robot names the type it subscribes.
    """

    backend: Literal["sim", "ros2"]  # required: a robot must never drive a simulated base
    watchdog_s: Positive = 0.25
    commander: str = "nav"
    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=200)] = 50.0
    # the odometry's stated variances: ``var_v`` (m/s)^2; for the turn rate the
    # encoders' noise ``var_w`` (rad/s)^2 plus the skid-steer's scrub, which grows with
    # the rate: ``turn_slip_sd`` of it, 1 sigma (the body yaws at 0.93 of the
    # wheel-implied rate on firm soil and less on loose, unknown to the encoders). A
    # constant variance sized for 0.6 rad/s turns would call a 0.005 rad/s heading
    # trim 60 times noisier than it is, and the moving GNSS compass would then pull
    # the settled heading by its own error (0.6 deg per fix) during every trim.
    var_v: Annotated[float, msgspec.Meta(ge=0)] = 1e-4
    var_w: Annotated[float, msgspec.Meta(ge=0)] = 1e-4
    turn_slip_sd: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.1
    ros2_cmd_vel: Topic = "cmd_vel"
    ros2_cmd_vel_type: CmdVelType = "Twist"
    ros2_cmd_vel_frame: str = BASE_FRAME
    ros2_odom: Topic = "odom"
    ros2_scan: Topic = "scan"
    ros2_imu: Topic = "imu/data"
    ros2_battery: Topic = "battery_state"
    ros2_layout: Literal["rmw_zenoh", "bridge"] = "rmw_zenoh"
    # ROS_DOMAIN_ID's range (0-232: what DDS port arithmetic allows, kept by rmw_zenoh)
    ros2_domain: Annotated[int, msgspec.Meta(ge=0, le=232)] = 0
    ros2_namespace: Annotated[str, msgspec.Meta(pattern=NAMESPACE_PATTERN)] = "/"
    ros2_node: Annotated[str, msgspec.Meta(pattern=NAME_PATTERN)] = "phenorover_base"
    ros2_odom_timeout_s: Positive = 0.5
