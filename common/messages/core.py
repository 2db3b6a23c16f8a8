"""Base types shared by every message.

Conventions (see docs/architecture.md, "Messages"):
- every message is a frozen msgspec Struct deriving from :class:`Message`, so it
  carries ``stamp_ns`` (nanoseconds, on the clock of the publishing service: wall
  time, or sim time in simulation) and ``frame_id`` (REP-103/105 frame name);
- units are SI (metres, radians, seconds) unless a field name says otherwise;
- new fields get defaults and go at the end, so old decoders keep working
  (unknown fields are ignored when decoding messages, unlike configs);
- arrays travel as :class:`Array` (dtype, shape, raw bytes);
- every float is finite by schema: a NaN or an infinity fails decoding like any
  other out-of-range value (the aliases below; ``tests/common/test_messages_finite.py``
  checks every field of every message on the bus).
"""

from __future__ import annotations

import math
from typing import Annotated, Any

import msgspec
import numpy as np
import numpy.typing as npt

# msgspec checks bounds on decode only, by comparison, and NaN fails every comparison:
# so a lower *and* an upper bound on a float refuse NaN, +inf and -inf alike. 1e300
# lets every real value through.
FINITE_MAX = 1e300
#: Any finite float.
Finite = Annotated[float, msgspec.Meta(ge=-FINITE_MAX, le=FINITE_MAX)]
#: A finite float >= 0 (variances, durations, distances).
NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=FINITE_MAX)]
#: A finite float > 0.
Positive = Annotated[float, msgspec.Meta(gt=0.0, le=FINITE_MAX)]
Probability = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
#: A random generator's seed (numpy's take no negative one).
Seed = Annotated[int, msgspec.Meta(ge=0, le=2**63 - 1)]
#: An angle in radians within two turns either way: every producer wraps to
#: (-pi, pi]; the slack lets through one that wraps late, not garbage.
Angle = Annotated[float, msgspec.Meta(ge=-4.0 * math.pi, le=4.0 * math.pi)]
#: A body speed, m/s or rad/s: the robot does 1 m/s and 2 rad/s, nothing on the
#: ground does 100.
Velocity = Annotated[float, msgspec.Meta(ge=-100.0, le=100.0)]
#: A coordinate in a local frame (``map``, ``field``, ``odom``), metres: within
#: 10,000 km of the frame's origin, a quarter of the way round the earth.
Coordinate = Annotated[float, msgspec.Meta(ge=-1e7, le=1e7)]
#: WGS84 degrees and metres above the ellipsoid (the earth's surface spans about
#: -500 m to 9 km; the slack covers aircraft and a bad geoid model, not garbage).
Latitude = Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
Longitude = Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
Altitude = Annotated[float, msgspec.Meta(ge=-1e4, le=1e5)]
#: A name that becomes a folder or file name on another machine (a mission, a scan
#: project): letters, digits, ``._-``, not starting with a dot, at most 64; or empty.
FileName = Annotated[str, msgspec.Meta(pattern=r"^([A-Za-z0-9_-][A-Za-z0-9._-]{0,63})?$")]

# dtypes allowed on the wire: fixed-size little-endian numbers only.
_WIRE_DTYPES = frozenset(
    {"<f4", "<f8", "<i1", "<i2", "<i4", "<i8", "|u1", "<u2", "<u4", "<u8", "|b1", "|i1"}
)


# A robot's namespace (common.keys.in_namespace): one chunk of a key, no slash, no
# wildcard, nothing Zenoh reserves; "" is none (a robot surveying alone)
NAMESPACE_PATTERN = r"^[A-Za-z0-9_-]{0,32}$"
Namespace = Annotated[str, msgspec.Meta(pattern=NAMESPACE_PATTERN)]
# a robot named among others: a namespace that is not empty
RobotName = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_-]{1,32}$")]

# The frames messages are stamped in (REP-103/105 names; ``field`` is the survey's own
# frame, :mod:`common.field`): one spelling for every publisher
FIELD_FRAME = "field"
ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
IMU_FRAME = "imu_link"
LASER_FRAME = "laser"
SCANNER_FRAME = "scanner"


class Message(msgspec.Struct, frozen=True, kw_only=True):
    """Base of all bus messages: a time stamp and the frame the data is expressed in."""

    stamp_ns: int = 0
    frame_id: str = ""


class Array(msgspec.Struct, frozen=True):
    """An n-dimensional numeric array on the wire: ``dtype`` is a numpy dtype string
    such as ``"<f4"``, ``shape`` its dimensions, ``data`` the C-ordered raw bytes."""

    dtype: str
    shape: tuple[int, ...]
    data: bytes

    @classmethod
    def of(cls, a: npt.ArrayLike) -> Array:
        arr = np.asarray(a)
        if not arr.flags.c_contiguous:
            arr = arr.copy(order="C")
        dt = arr.dtype.newbyteorder("<") if arr.dtype.byteorder == ">" else arr.dtype
        arr = arr.astype(dt, copy=False)
        return cls(dtype=dt.str, shape=tuple(int(s) for s in arr.shape), data=arr.tobytes())

    def numpy(self) -> npt.NDArray[Any]:
        """The array as numpy (read-only view of ``data``).

        Raises ValueError when dtype, shape and data length disagree, which is what a
        corrupted or hostile message looks like.
        """
        if self.dtype not in _WIRE_DTYPES:
            raise ValueError(f"Array.dtype {self.dtype!r} is not a supported wire dtype")
        dt = np.dtype(self.dtype)
        if any(s < 0 for s in self.shape):
            raise ValueError(f"Array.shape {self.shape} has a negative dimension")
        n = int(np.prod(self.shape, dtype=np.int64))
        if n * dt.itemsize != len(self.data):
            raise ValueError(
                f"Array of shape {self.shape} and dtype {self.dtype} needs "
                f"{n * dt.itemsize} bytes, got {len(self.data)}"
            )
        return np.frombuffer(self.data, dtype=dt).reshape(self.shape)


class Vector3(msgspec.Struct, frozen=True):
    """A 3-vector in metres (or m/s, rad/s, by context)."""

    x: Finite = 0.0
    y: Finite = 0.0
    z: Finite = 0.0


class Pose2D(msgspec.Struct, frozen=True):
    """A planar pose: position in metres, ``yaw`` in radians (REP-103: 0 along +x,
    counter-clockwise positive), in the frame of the enclosing message."""

    x: Coordinate = 0.0
    y: Coordinate = 0.0
    yaw: Angle = 0.0
