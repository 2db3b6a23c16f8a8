from __future__ import annotations

import dataclasses
from typing import Annotated

import msgspec

from common.config import ConfigError
from common.messages.core import NonNegative, Positive
from common.robot import Robot
from services.nav.ekf import EkfConfig
from services.nav.follower_config import FollowerConfig
from services.nav.gyro import GyroConfig
from services.nav.tilt import TiltConfig


class NavConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """EKF localization and route following; the antennas, the lidar and the robot's
    front are the robot description's (:class:`Mounts`)."""

    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=200)] = 20.0
    """Pose and velocity command rate."""
    ekf: EkfConfig = msgspec.field(default_factory=EkfConfig)
    """The localization filter (docs/navigation.md)."""
    tilt: TiltConfig = msgspec.field(default_factory=TiltConfig)
    """base_link's roll and pitch from the IMU, which put the antennas' lever arms in 3D
    (:mod:`services.nav.tilt`)."""
    gyro: GyroConfig = msgspec.field(default_factory=GyroConfig)
    """The IMU's yaw rate fused beside the wheels' (:mod:`services.nav.gyro`)."""
    follower: FollowerConfig = msgspec.field(default_factory=FollowerConfig)
    """Route following (docs/navigation.md)."""
    fuse_fix_types: list[str] = msgspec.field(default_factory=lambda: ["FIX"])
    """GGA fix types whose positions are fused. RTK-fixed only by default: float errors
    (decimetres) are correlated over tens of seconds, and fusing them at 10 Hz as if
    independent makes the filter overconfident enough to reject the fixed solutions
    that follow; during float the filter dead-reckons on odometry instead."""
    obstacle_distance_m: Positive = 0.6
    """The lidar stop box: how far ahead of the robot's front an obstacle stops it."""
    obstacle_half_width_m: Positive = 0.30
    """The stop box's reach to each side of the lane: the Husky is 0.67 m wide, and plot
    edges beside a 0.8 m row gap stand 0.4 m from the lane's centre; 0.30 m keeps them 4
    sigma of lidar noise plus a few cm of cross-track error out, at the price of missing
    an obstacle that overlaps only the robot's outer 3.5 cm."""
    obstacle_min_points: Annotated[int, msgspec.Meta(ge=1)] = 3
    """Returns in the box, in ``obstacle_scans`` consecutive scans, stop the robot."""
    obstacle_scans: Annotated[int, msgspec.Meta(ge=1)] = 2
    """Consecutive scans with ``obstacle_min_points`` returns in the box that stop it."""
    obstacle_crop_margin_m: NonNegative = 0.15
    """Returns this close to a plot of the field are the crop, not an obstacle, while a
    route is followed: under the canopy the estimate may be 10 cm off, which places a
    plot's edge 0.40 m from the lane's centre at 0.30 m, inside the box, and a plot never
    moves out of the way. An obstacle that close to a plot is missed; one in the lane's
    middle 0.5 m is not."""
    still_after_s: Positive = 1.0
    """How long after the last non-zero velocity command the robot counts as standing
    (the drivetrain's lag is 0.15 s), provided its odometry reads still too (within 4
    sigma of the encoders' noise); the filter then makes zero-velocity updates."""
    route_margin_m: Positive = 25.0
    """A route with a leg ending farther than this outside the field's boundary is
    refused (reply ``accepted = false``, the reason names the leg): the survey, the
    drive home and the experiments stay within metres of it, so such a route is
    mistyped or forged, and following it would turn the robot towards it."""
    max_fix_age_s: Positive = 0.25
    """The dead-reckoning allowance: with no RTK-fixed position fused for this long the
    robot is not localized and stops. 0.25 s (one fix at 10 Hz may go missing) at 0.5 m/s
    is 0.125 m on odometry (a millimetre of drift); braking from 0.5 m/s at the Husky's
    1 m/s² with the drivetrain's 0.15 s lag takes another 0.6 s, so the robot is below
    2 cm/s within 1 s of the last fix. A sim running many times faster than real time
    needs more: a fix late by 50 ms of wall time is late by 0.5 s of sim time at 10x
    (deploy/sim.toml says so)."""


@dataclasses.dataclass(frozen=True)
class Mounts:
    """What navigation uses of the robot description, in base_link (m, rad):
    ``levers``: (x, y, z) of antennas 1 and 2, turned by the tilt into the EKF's
    planar lever arms and the heights taken off a fix's altitude for base_link's
    ``z``; ``scanner_yaw``: the scanner's mount yaw (its compensator's axes);
    ``lidar``: (x, y, yaw) of the lidar; ``front``: x of the robot's front."""

    levers: tuple[tuple[float, float, float], tuple[float, float, float]]
    scanner_yaw: float
    lidar: tuple[float, float, float]
    front: float

    @classmethod
    def of(cls, robot: Robot) -> Mounts:
        a1, a2 = robot.antennas
        return cls(
            levers=(a1.xyz, a2.xyz),
            scanner_yaw=robot.scanner.yaw_rad,
            lidar=(robot.lidar.x, robot.lidar.y, robot.lidar.yaw_rad),
            front=robot.footprint.length / 2.0,
        )


def check_limits(cfg: NavConfig, robot: Robot) -> None:
    """Raise ConfigError (one line) when the route follower is set to go faster or
    accelerate harder than the robot can: it would then plan for motion the drivetrain
    clips, and overshoot every stop."""
    for key in ("max_speed", "max_accel", "max_turn_rate", "max_turn_accel"):
        value, limit = getattr(cfg.follower, key), getattr(robot.limits, key)
        if value > limit:
            raise ConfigError(
                f"[services.nav.follower] {key} = {value:g} is more than robot "
                f"{robot.name}'s [limits] {key} = {limit:g}"
            )
