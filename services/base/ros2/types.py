"""The ROS 2 message types phenorover speaks, each with its name, CDR class and
RIHS01 hash: one place that ties a topic's key to how its payload decodes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

from services.base.ros2 import msgs
from services.base.ros2.wire import TYPE_HASHES, dds_type_name

T = TypeVar("T")


@dataclass(frozen=True)
class RosType(Generic[T]):
    """``name`` as ROS writes it (``geometry_msgs/msg/Twist``), ``cls`` the pycdr2
    struct that (de)serializes it with the CDR encapsulation header."""

    name: str
    cls: type[T]

    @property
    def type_hash(self) -> str:
        return TYPE_HASHES[self.name]

    @property
    def dds_name(self) -> str:
        return dds_type_name(self.name)

    def encode(self, msg: T) -> bytes:
        data: bytes = self._cdr(msg).serialize()
        return data

    def decode(self, data: bytes) -> T:
        """Raises (any exception) on bytes that are not this type's CDR."""
        msg: T = self._struct().deserialize(data)
        return msg

    def _cdr(self, msg: T) -> Any:
        if type(msg) is not self.cls:
            raise TypeError(f"{self.name} is {self.cls.__name__}, not {type(msg).__name__}")
        return msg

    def _struct(self) -> Any:
        return self.cls


TWIST = RosType("geometry_msgs/msg/Twist", msgs.Twist)
TWIST_STAMPED = RosType("geometry_msgs/msg/TwistStamped", msgs.TwistStamped)
ODOMETRY = RosType("nav_msgs/msg/Odometry", msgs.Odometry)
LASER_SCAN = RosType("sensor_msgs/msg/LaserScan", msgs.LaserScan)
IMU = RosType("sensor_msgs/msg/Imu", msgs.Imu)
BATTERY_STATE = RosType("sensor_msgs/msg/BatteryState", msgs.BatteryState)

# what a base driver takes on ``cmd_vel``, by the name a manifest gives: Clearpath's
# ROS 2 Jazzy platform takes TwistStamped, most other drivers (and Humble's) Twist
CmdVelType = Literal["Twist", "TwistStamped"]
CMD_VEL_TYPES: dict[str, RosType[Any]] = {"Twist": TWIST, "TwistStamped": TWIST_STAMPED}


def twist_of(msg: msgs.Twist | msgs.TwistStamped) -> msgs.Twist:
    """The velocities of a command of either type."""
    return msg.twist if isinstance(msg, msgs.TwistStamped) else msg
