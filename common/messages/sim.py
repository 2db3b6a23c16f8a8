"""Simulated world: clock and ground truth. Truth is for evaluation only: no
non-sim service may read it."""

from __future__ import annotations

from typing import Annotated

import msgspec

from common.messages.core import (
    Angle,
    Coordinate,
    Finite,
    Message,
    NonNegative,
    Velocity,
)


class SimClock(Message, frozen=True, kw_only=True):
    """The simulator's clock, ``sim_ns`` nanoseconds since the world started.

    ``real_time_factor`` is sim seconds per wall second (10 = ten times faster).
    Services on a sim clock stamp their messages with ``sim_ns``.
    """

    sim_ns: Annotated[int, msgspec.Meta(ge=0)]
    # the simulator's own config caps it at 1000; a follower that received 1e6 would
    # believe the world may run a million times faster than the wall clock
    real_time_factor: Annotated[float, msgspec.Meta(gt=0, le=1e6)] = 1.0
    # lockstep (common/lockstep.py): the step's number (-1: a world that does not
    # wait), and per "<service>|<key>" how many messages the step expects delivered
    step: int = -1
    expect: dict[str, int] = msgspec.field(default_factory=dict)
    # lockstep's roll call, before the world's first step: each participant only
    # acknowledges it with its counts (every message it published before the world
    # began is then expected in that first step), taking nothing in, running nothing
    roll_call: bool = False


class SimRun(Message, frozen=True, kw_only=True):
    """Let a simulator started held (``start_held``) step its world; with
    ``real_time_factor``, pace it at that from now on (a world whose robot only
    stands, while its scans are registered, needs no speed and leaves the CPU to
    the registration)."""

    real_time_factor: Annotated[float, msgspec.Meta(gt=0, le=1000)] | None = None


class ClockAck(Message, frozen=True, kw_only=True):
    """A lockstep participant has done the step at ``sim_ns``; ``published``: how many
    messages it has published so far, per key."""

    service: str
    sim_ns: Annotated[int, msgspec.Meta(ge=0)]
    published: dict[str, int] = msgspec.field(default_factory=dict)
    roll_call: bool = False  # the answer to a roll call (``SimClock.roll_call``)
    # the name its messages go by (common.mailbox.Outbox: changes with a restart)
    sender: str = ""


class TruthPose(Message, frozen=True, kw_only=True):
    """The robot's true pose (base_link in the ``field`` frame): metres and radians,
    ZYX Euler angles (yaw about z, then pitch, then roll)."""

    x: Coordinate
    y: Coordinate
    z: Coordinate
    roll: Angle = 0.0
    pitch: Angle = 0.0
    yaw: Angle = 0.0
    v: Velocity = 0.0
    w: Velocity = 0.0


class SimAntennas(Message, frozen=True, kw_only=True):
    """True phase-centre positions of both GNSS antennas in the ``field`` frame
    (metres): what the simulated receivers measure, before their error model.

    The fields after ``p2`` are injected faults (simulation only, scheduled in the
    simulator's config, see ``services/sim/faults.py``), per antenna 1 and 2:
    ``outage*``: the receiver sends nothing; ``force_float*``: it reports RTK float
    with float noise; ``offset*``: (east, north) metres added to what it reports,
    its fix quality unchanged (multipath). The positions stay the truth.
    ``blocked1``, ``blocked2``: the share of each antenna's sky (above a 15 deg mask)
    the crop hides, the world's, not a fault (:mod:`services.sim.sky`)."""

    p1: tuple[Coordinate, Coordinate, Coordinate]
    p2: tuple[Coordinate, Coordinate, Coordinate]
    outage1: bool = False
    outage2: bool = False
    force_float1: bool = False
    force_float2: bool = False
    offset1: tuple[Finite, Finite] = (0.0, 0.0)
    offset2: tuple[Finite, Finite] = (0.0, 0.0)
    blocked1: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.0
    blocked2: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.0


class SimWheelCommand(Message, frozen=True, kw_only=True):
    """What the simulated base's motor controller is asked for: body velocities
    (m/s, rad/s) the wheels are driven to, before slip."""

    v: Velocity
    w: Velocity


class SimEncoders(Message, frozen=True, kw_only=True):
    """Body velocities as the wheel encoders see them (m/s, rad/s): blind to slip."""

    v: Velocity
    w: Velocity


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
    pitch: Angle
    roll: Angle
    render_s: NonNegative
