"""Base types shared by every message.

Conventions (see README, "Messages"):
- every message is a frozen msgspec Struct deriving from :class:`Message`, so it
  carries ``stamp_ns`` (nanoseconds, on the clock of the publishing service: wall
  time, or sim time in simulation) and ``frame_id`` (REP-103/105 frame name);
- units are SI (metres, radians, seconds) unless a field name says otherwise;
- new fields get defaults and go at the end, so old decoders keep working
  (unknown fields are ignored when decoding messages, unlike configs);
- arrays travel as :class:`Array` (dtype, shape, raw bytes).
"""

from __future__ import annotations

from typing import Annotated, Any

import msgspec
import numpy as np
import numpy.typing as npt

NonNegative = Annotated[float, msgspec.Meta(ge=0.0)]
Probability = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
#: A name that becomes a folder or file name on another machine (a mission, a scan
#: project): letters, digits, ``._-``, not starting with a dot, at most 64; or empty.
FileName = Annotated[str, msgspec.Meta(pattern=r"^([A-Za-z0-9_-][A-Za-z0-9._-]{0,63})?$")]

# dtypes allowed on the wire: fixed-size little-endian numbers only.
_WIRE_DTYPES = frozenset(
    {"<f4", "<f8", "<i1", "<i2", "<i4", "<i8", "|u1", "<u2", "<u4", "<u8", "|b1", "|i1"}
)


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

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class Pose2D(msgspec.Struct, frozen=True):
    """A planar pose: position in metres, ``yaw`` in radians (REP-103: 0 along +x,
    counter-clockwise positive), in the frame of the enclosing message."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
