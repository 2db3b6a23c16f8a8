"""The robot description: where each sensor sits on the robot, how big it is and how
fast it may go, read from one TOML file.

Frame ``base_link`` (REP-103): x forward, y left, z up, metres; its origin is on the
plane through the four wheel contacts, midway between them, so on flat ground a z is a
height above the ground. Angles are degrees in the file (counter-clockwise about z,
REP-103 signs for roll and pitch), radians through the ``*_rad`` properties.

The manifest's ``robot`` names the file (:func:`robot_path`); ``common/robots/husky.toml``
is the paper's Clearpath Husky A200 and the default. gnss (compass), nav (antenna
levers, lidar, footprint, limits), base (limits), sim (antenna truth, scanner, lidar,
wheels, limits, battery), register (scanner and antenna levers), viz (body, lidar,
scanner), the planner (battery) and the mission (the scanner height it plans with, the
battery) read it; none keeps a copy.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Annotated

import msgspec

from common.battery import Battery
from common.config import ConfigError, one_line

ROBOTS_DIR = Path(__file__).with_name("robots")
DEFAULT = "husky"
# a mission keeps the description it ran with in its run folder, so a registration
# redone later, anywhere, places the scans with the robot that took them
RUN_COPY = "robot.toml"

# Every float finite by schema (NaN and inf fail a two-sided bound).
Coord = Annotated[float, msgspec.Meta(ge=-10.0, le=10.0)]  # a point on the robot (m)
Size = Annotated[float, msgspec.Meta(gt=0.0, le=10.0)]  # m
Angle = Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]  # degrees
Speed = Annotated[float, msgspec.Meta(gt=0.0, le=20.0)]  # m/s, rad/s
Accel = Annotated[float, msgspec.Meta(gt=0.0, le=100.0)]  # m/s^2, rad/s^2
Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_.-]{1,64}$")]

# closer than this, two antennas give a heading too noisy to steer by (a 7 mm fix
# error is 4 deg at 0.1 m)
MIN_BASELINE_M = 0.1


class _At:
    """``xyz`` of a part with ``x``, ``y``, ``z`` fields; each part declares the fields
    itself, with its own bounds and attribute docstrings (the generated docs read them)."""

    __slots__ = ()
    x: float
    y: float
    z: float

    @property
    def xyz(self) -> tuple[float, float, float]:
        return (self.x, self.y, self.z)


class _Yawed:
    """``yaw_rad`` of a part with a ``yaw_deg`` field (declared by the part, as for
    :class:`_At`)."""

    __slots__ = ()
    yaw_deg: float

    @property
    def yaw_rad(self) -> float:
        return math.radians(self.yaw_deg)


class GnssAntenna(_At, msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A GNSS antenna's phase centre (:attr:`Robot.antennas`)."""

    name: Name
    """The antenna's frame (``gnss_1``)."""
    x: Coord
    """The phase centre's x in base_link (m)."""
    y: Coord
    """The phase centre's y in base_link (m)."""
    z: Coord
    """The phase centre's z in base_link (m)."""


class ScannerMount(
    _At, _Yawed, msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True
):
    """The TLS's mount (:attr:`Robot.scanner`)."""

    x: Coord
    """The optical centre's x in base_link (m)."""
    y: Coord
    """The optical centre's y in base_link (m)."""
    z: Size
    """The optical centre's height in base_link (m): the planner casts its rays from this
    height above the ground."""
    yaw_deg: Angle = 0.0
    """The scanner's zero azimuth from base_link x (deg)."""


class LidarMount(
    _At, _Yawed, msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True
):
    """The 2D lidar's mount (:attr:`Robot.lidar`)."""

    x: Coord
    """The scan plane's centre's x in base_link (m)."""
    y: Coord
    """The scan plane's centre's y in base_link (m)."""
    z: Coord
    """The scan plane's height in base_link (m)."""
    yaw_deg: Angle = 0.0
    """The direction of its 0-degree beam from base_link x (deg)."""


class ImuMount(_Yawed, msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The IMU's mount (:attr:`Robot.imu`)."""

    x: Coord = 0.0
    """The unit's origin's x in base_link (m)."""
    y: Coord = 0.0
    """The unit's origin's y in base_link (m)."""
    z: Coord = 0.0
    """The unit's origin's z in base_link (m)."""
    roll_deg: Angle = 0.0
    """The unit's roll in base_link (deg)."""
    pitch_deg: Angle = 0.0
    """The unit's pitch in base_link (deg)."""
    yaw_deg: Angle = 0.0
    """The unit's yaw in base_link (deg)."""

    @property
    def roll_rad(self) -> float:
        return math.radians(self.roll_deg)

    @property
    def pitch_rad(self) -> float:
        return math.radians(self.pitch_deg)


class Footprint(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The body's box (:attr:`Robot.footprint`)."""

    length: Size
    """The box along x (m)."""
    width: Size
    """The box along y (m)."""
    height: Size
    """The box up (m)."""


class Limits(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """What the drivetrain can do (:attr:`Robot.limits`)."""

    max_speed: Speed
    """The fastest linear speed (m/s)."""
    max_turn_rate: Speed
    """The fastest turn rate (rad/s)."""
    max_accel: Accel
    """The largest linear acceleration (m/s²)."""
    max_turn_accel: Accel
    """The largest angular acceleration (rad/s²)."""


class Robot(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """One robot."""

    name: Name
    """The robot's name."""
    antennas: tuple[GnssAntenna, GnssAntenna]
    """The two GNSS antennas, antenna 1 first (its fixes are ``gnss/1/fix``); the compass
    heading is that of the 1 -> 2 vector less its yaw in base_link."""
    scanner: ScannerMount
    """The TLS: its optical centre and zero azimuth. Its tilt is not described: the
    scanner's own compensator measures pitch and roll at every scan."""
    lidar: LidarMount
    """The 2D lidar: its scan plane, level with base_link, and its 0-degree beam."""
    imu: ImuMount = ImuMount()
    """The IMU's mount (ZYX Euler angles): navigation turns the unit's roll and pitch
    into base_link's through it."""
    footprint: Footprint
    """The body as a box centred on base_link in x and y, standing on the ground."""
    track: Size
    """The distance between the left and right wheels' contact lines (m)."""
    wheelbase: Size
    """The distance between the front and rear axles (m)."""
    limits: Limits
    """What the drivetrain can do: the base clips commands to it, and navigation refuses
    a follower set faster."""
    battery: Battery = Battery()
    """What it carries and draws: the simulator discharges by it, the planner and the
    mission plan the swaps with it (:mod:`common.battery`)."""

    def __post_init__(self) -> None:
        a, b = self.antennas
        if a.name == b.name:
            raise ValueError(f"antennas: both are named {a.name!r}")
        if math.dist(a.xyz, b.xyz) < MIN_BASELINE_M:
            raise ValueError(
                f"antennas: {a.name} and {b.name} are {math.dist(a.xyz, b.xyz):.3f} m apart, "
                f"less than the {MIN_BASELINE_M} m a GNSS compass needs"
            )
        if self.track > self.footprint.width or self.wheelbase > self.footprint.length:
            raise ValueError(
                f"track x wheelbase {self.track} x {self.wheelbase} m is outside the "
                f"footprint {self.footprint.width} x {self.footprint.length} m"
            )

    @property
    def antenna_height(self) -> float:
        """The antennas' mean height above base_link (m)."""
        return (self.antennas[0].z + self.antennas[1].z) / 2.0


def example_names() -> list[str]:
    """Names of the robot descriptions shipped in ``common/robots``."""
    return sorted(p.stem for p in ROBOTS_DIR.glob("*.toml"))


def robot_path(source: str | Path = "") -> Path:
    """The file a robot source names: empty for the default (the Husky), the path
    itself, or for a bare name (no folder, no suffix) that is not a file here, the
    shipped ``common/robots/NAME.toml``. Raises ConfigError when there is no such one."""
    source = str(source) or DEFAULT
    path = Path(source)
    if not path.exists() and path.suffix == "" and "/" not in source:
        shipped = ROBOTS_DIR / f"{source}.toml"
        if shipped.exists():
            return shipped
        raise ConfigError(
            f"{source}: no such robot description file or example "
            f"(examples: {', '.join(example_names())})"
        )
    return path


def load_robot(source: str | Path = "") -> Robot:
    """The robot description ``source`` names (see :func:`robot_path`).

    Raises ConfigError with one line naming the file and the key at fault, e.g.
    ``husky.toml: Expected `float` <= 10.0 - at `$.antennas[1].x```."""
    path = robot_path(source)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        return msgspec.toml.decode(data, type=Robot)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{path}: {one_line(exc)}") from None
    except msgspec.DecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {one_line(exc)}") from None


@functools.cache
def default_robot() -> Robot:
    """The shipped default (``common/robots/husky.toml``), read once."""
    return load_robot(DEFAULT)


def dump_robot(robot: Robot) -> str:
    """``robot`` as TOML that :func:`load_robot` reads back to an equal description."""
    return msgspec.toml.encode(robot).decode()
