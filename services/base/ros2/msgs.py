"""ROS 2 messages as CDR (pycdr2): what the base's ``ros2`` backend and the simulated
Husky driver put on the wire, under either key layout (rmw_zenoh or
zenoh-bridge-ros2dds), and the builders that make them from plain values. The types
are declared in :mod:`services.base.ros2.idl` (ROS 2 Jazzy's field layouts exactly) and read
from here; payloads carry the 4-byte CDR encapsulation header (little-endian, ``00 01
00 00``), as rmw_zenoh's FastCDR (DDS_CDR mode) writes them.
"""

# mypy: disable-error-code="arg-type"
# (the builders take plain Python values where pycdr2 declares subscripted IDL types,
# which mypy cannot see a list is one of.)

import math
import warnings

from scipy.spatial.transform import Rotation

from services.base.ros2.idl import (
    BatteryState,
    Header,
    Imu,
    LaserScan,
    Odometry,
    Point,
    Pose,
    PoseWithCovariance,
    Quaternion,
    Time,
    Twist,
    TwistStamped,
    TwistWithCovariance,
    Vector3,
)

# gimbal lock is documented where it arises (euler_of), not an error; one filter for
# the process, as catch_warnings() around each call is not thread-safe
warnings.filterwarnings("ignore", message="Gimbal lock detected", category=UserWarning)

__all__ = [
    "POWER_SUPPLY_HEALTH_GOOD",
    "POWER_SUPPLY_STATUS_DISCHARGING",
    "POWER_SUPPLY_TECHNOLOGY_UNKNOWN",
    "BatteryState",
    "Header",
    "Imu",
    "LaserScan",
    "Odometry",
    "Point",
    "Pose",
    "PoseWithCovariance",
    "Quaternion",
    "Time",
    "Twist",
    "TwistStamped",
    "TwistWithCovariance",
    "Vector3",
    "battery_state",
    "euler_of",
    "imu",
    "laser_scan",
    "ns_of_time",
    "odometry",
    "quaternion_of_euler",
    "quaternion_of_yaw",
    "time_of_ns",
    "twist",
    "twist_stamped",
    "yaw_of",
]


def twist(v: float, w: float) -> Twist:
    """A planar velocity command: ``v`` m/s along x, ``w`` rad/s about z."""
    return Twist(Vector3(v, 0.0, 0.0), Vector3(0.0, 0.0, w))


def twist_stamped(v: float, w: float, stamp_ns: int, frame_id: str) -> TwistStamped:
    """:func:`twist` with a header. ros2_controllers' diff_drive_controller (Clearpath's
    Jazzy platform) measures a command's age from this stamp against its own clock and
    brakes past ``cmd_vel_timeout``, so the stamp must be the robot's clock, now."""
    return TwistStamped(Header(time_of_ns(stamp_ns), frame_id), twist(v, w))


# sensor_msgs/BatteryState's constants
POWER_SUPPLY_STATUS_DISCHARGING = 2
POWER_SUPPLY_HEALTH_GOOD = 1
POWER_SUPPLY_TECHNOLOGY_UNKNOWN = 0


def battery_state(
    stamp_ns: int, percentage: float, voltage: float, current: float, capacity_ah: float
) -> BatteryState:
    """A discharging battery's state as a driver publishes it: ``percentage`` 0-1,
    ``voltage`` (V), ``current`` (A, negative out of the battery), ``capacity_ah`` its
    full charge; unmeasured fields NaN, as sensor_msgs asks."""
    nan = math.nan
    return BatteryState(
        header=Header(time_of_ns(stamp_ns), ""),
        voltage=voltage,
        temperature=nan,
        current=current,
        charge=percentage * capacity_ah,
        capacity=capacity_ah,
        design_capacity=capacity_ah,
        percentage=percentage,
        power_supply_status=POWER_SUPPLY_STATUS_DISCHARGING,
        power_supply_health=POWER_SUPPLY_HEALTH_GOOD,
        power_supply_technology=POWER_SUPPLY_TECHNOLOGY_UNKNOWN,
        present=True,
        cell_voltage=[],
        cell_temperature=[],
        location="",
        serial_number="",
    )


def yaw_of(q: Quaternion) -> float:
    """Yaw (rad, about z) of a quaternion."""
    return euler_of(q)[2]


def quaternion_of_yaw(yaw: float) -> Quaternion:
    """The unit quaternion of a rotation by ``yaw`` rad about z."""
    return quaternion_of_euler(0.0, 0.0, yaw)


def quaternion_of_euler(roll: float, pitch: float, yaw: float) -> Quaternion:
    """The unit quaternion of ZYX Euler angles (rad): yaw about z, then pitch about the
    new y, then roll about the new x (REP-103's roll, pitch, yaw)."""
    x, y, z, w = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
    return Quaternion(float(x), float(y), float(z), float(w))


def euler_of(q: Quaternion) -> tuple[float, float, float]:
    """ZYX Euler angles (roll, pitch, yaw; rad) of a quaternion, normalised first (a
    zero quaternion reads as no rotation). Pitch is in [-pi/2, pi/2]; at +-pi/2 roll
    and yaw are not separable (gimbal lock). Raises ValueError for a quaternion that
    is not finite or too short to normalise."""
    if q.x == q.y == q.z == q.w == 0.0:
        return 0.0, 0.0, 0.0
    c = (q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in c):
        raise ValueError(f"quaternion {c} is not finite")
    yaw, pitch, roll = Rotation.from_quat(c).as_euler("ZYX")  # ValueError: zero norm
    return float(roll), float(pitch), float(yaw)


def time_of_ns(stamp_ns: int) -> Time:
    """builtin_interfaces/Time of nanoseconds (floor division: negative stamps too)."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return Time(sec, nanosec)


def ns_of_time(t: Time) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def odometry(
    stamp_ns: int,
    frame_id: str,
    child_frame_id: str,
    pose: tuple[float, float, float],
    twist_vw: tuple[float, float],
    pose_covariance: list[float],
    twist_covariance: list[float],
) -> Odometry:
    """A planar nav_msgs/Odometry: ``pose`` (x m, y m, yaw rad) of ``child_frame_id``
    in ``frame_id``, ``twist_vw`` (v m/s, w rad/s) in the child frame, row-major 6x6
    covariances (36 values each)."""
    x, y, yaw = pose
    return Odometry(
        header=Header(time_of_ns(stamp_ns), frame_id),
        child_frame_id=child_frame_id,
        pose=PoseWithCovariance(Pose(Point(x, y, 0.0), quaternion_of_yaw(yaw)), pose_covariance),
        twist=TwistWithCovariance(twist(*twist_vw), twist_covariance),
    )


def laser_scan(
    stamp_ns: int,
    frame_id: str,
    angles: tuple[float, float, float],
    range_limits: tuple[float, float],
    ranges: list[float],
) -> LaserScan:
    """sensor_msgs/LaserScan of ``angles`` (min, max, increment; rad), ``range_limits``
    (min, max; m) and ``ranges`` (m); no timing nor intensities."""
    return LaserScan(
        header=Header(time_of_ns(stamp_ns), frame_id),
        angle_min=angles[0],
        angle_max=angles[1],
        angle_increment=angles[2],
        time_increment=0.0,
        scan_time=0.0,
        range_min=range_limits[0],
        range_max=range_limits[1],
        ranges=ranges,
        intensities=[],
    )


def imu(
    stamp_ns: int,
    frame_id: str,
    rpy: tuple[float, float, float],
    angular_velocity: tuple[float, float, float],
    linear_acceleration: tuple[float, float, float],
    tilt_var: float,
    yaw_var: float = 0.0,
    angular_velocity_var: float = 0.0,
    linear_acceleration_var: float = 0.0,
) -> Imu:
    """sensor_msgs/Imu of ``frame_id``'s orientation ``rpy`` (ZYX Euler, rad), its
    angular velocity (rad/s) and specific force (m/s^2), each x y z. Covariances are
    diagonal: ``tilt_var`` for roll and pitch, ``yaw_var`` for yaw (rad^2), one
    variance for each vector's three axes; sensor_msgs reads all zeros as unknown."""
    return Imu(
        header=Header(time_of_ns(stamp_ns), frame_id),
        orientation=quaternion_of_euler(*rpy),
        orientation_covariance=_diagonal3(tilt_var, tilt_var, yaw_var),
        angular_velocity=Vector3(*angular_velocity),
        angular_velocity_covariance=_diagonal3(*(angular_velocity_var,) * 3),
        linear_acceleration=Vector3(*linear_acceleration),
        linear_acceleration_covariance=_diagonal3(*(linear_acceleration_var,) * 3),
    )


def _diagonal3(a: float, b: float, c: float) -> list[float]:
    """A row-major 3x3 covariance (9 values) with ``a``, ``b``, ``c`` on its diagonal."""
    return [float(a), 0.0, 0.0, 0.0, float(b), 0.0, 0.0, 0.0, float(c)]
