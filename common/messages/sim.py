"""Simulated world: clock and ground truth. Truth is for evaluation only: no
non-sim service may read it."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import Message


class SimClock(Message, frozen=True, kw_only=True):
    """The simulator's clock, ``sim_ns`` nanoseconds since the world started.

    ``real_time_factor`` is sim seconds per wall second (10 = ten times faster).
    Services on a sim clock stamp their messages with ``sim_ns``.
    """

    sim_ns: Annotated[int, msgspec.Meta(ge=0)]
    real_time_factor: Annotated[float, msgspec.Meta(gt=0)] = 1.0


class TruthPose(Message, frozen=True, kw_only=True):
    """The robot's true pose (base_link in the ``field`` frame): metres and radians,
    ZYX Euler angles (yaw about z, then pitch, then roll)."""

    x: float
    y: float
    z: float
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    v: float = 0.0
    w: float = 0.0


class SimAntennas(Message, frozen=True, kw_only=True):
    """True phase-centre positions of both GNSS antennas in the ``field`` frame
    (metres): what the simulated receivers measure, before their error model."""

    p1: tuple[float, float, float]
    p2: tuple[float, float, float]


class SimWheelCommand(Message, frozen=True, kw_only=True):
    """What the simulated base's motor controller is asked for: body velocities
    (m/s, rad/s) the wheels are driven to, before slip."""

    v: float
    w: float


class SimEncoders(Message, frozen=True, kw_only=True):
    """Body velocities as the wheel encoders see them (m/s, rad/s): blind to slip."""

    v: float
    w: float


class RenderRequest(Message, frozen=True, kw_only=True):
    """Ask the world to render a scan from the scanner's current true pose into
    ``path`` (an E57 file), at ``step_deg`` angular resolution."""

    scan_id: int
    path: str
    step_deg: Annotated[float, msgspec.Meta(gt=0, le=5)] = 0.36


class RenderReply(Message, frozen=True, kw_only=True):
    """The rendered scan: file written, point count, and the inclinometer's reading
    of the scanner's pitch and roll (radians, with its noise)."""

    path: str
    points: int
    pitch: float
    roll: float
    render_s: float
