from typing import Annotated, Literal

import msgspec

Pos = Annotated[float, msgspec.Meta(gt=0)]


class BaseConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The mobile base; the speed limits it clips commands to are the robot
    description's ``[limits]`` (:mod:`common.robot`). ``watchdog_s``: with no velocity
    command for this long the wheels are stopped: navigation commands at 20 Hz, so
    0.25 s is five missed commands, and a robot at 0.5 m/s whose navigation dies stands
    within 0.2 m (0.125 m to the trip, about 0.08 m of drivetrain lag).

    ``backend``: ``sim`` (the simulator's base) or ``ros2`` (any ROS 2 base, the
    Husky's own driver included, through zenoh-bridge-ros2dds: Twist out on
    ``ros2_cmd_vel``, Odometry in on ``ros2_odom``, LaserScan in on ``ros2_scan``).
    """

    backend: Literal["sim", "ros2"]  # required: a robot must never drive a simulated base
    watchdog_s: Pos = 0.25
    commander: str = "nav"
    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=200)] = 50.0
    # encoder noise the odometry reports as variance per unit travelled/turned
    var_v: Annotated[float, msgspec.Meta(ge=0)] = 1e-4
    var_w: Annotated[float, msgspec.Meta(ge=0)] = 4e-3
    ros2_cmd_vel: str = "cmd_vel"
    ros2_odom: str = "odom"
    ros2_scan: str = "scan"
