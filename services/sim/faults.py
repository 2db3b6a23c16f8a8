"""Faults injected into the simulated devices, scheduled from the manifest.

Each ``[[services.sim.faults]]`` entry is a :data:`Fault`: a ``kind``, a window of
sim time (``at_s``, ``for_s``: sim seconds since the world started, the clock on
``sim/clock``; active for ``at_s <= t < at_s + for_s``) and the kind's own fields.
This module only answers "what is wrong with the devices at sim time t"
(:class:`FaultSchedule`); the simulator applies the answer where it makes device
data. Faults change what devices report, never the truth: the robot's true pose,
the truth topic and the FARO's scene are the same with or without them (the
simulator draws the same random numbers either way).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import msgspec

from common.messages.core import Coordinate, Finite, NonNegative, Positive
from services.sim.world_config import BoxObstacle

Antenna = Literal[1, 2]
Encoders = Literal["ok", "zero", "silent"]


class _Window(
    msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, tag_field="kind"
):
    """A fault's window in sim seconds."""

    at_s: NonNegative
    """The fault starts this many sim seconds after the world started (the clock on
    ``sim/clock``)."""
    for_s: Positive
    """The fault lasts this long (sim s): on for ``at_s <= t < at_s + for_s``."""

    def active(self, t_s: float) -> bool:
        """On at sim time ``t_s`` (seconds)?"""
        return self.at_s <= t_s < self.at_s + self.for_s

    def detail(self) -> str:
        """The kind's own fields, for the simulator's log."""
        return ""


def _antennas(antenna: Antenna | None) -> str:
    return "both antennas" if antenna is None else f"antenna {antenna}"


class RtkOutage(_Window, frozen=True, kw_only=True, tag="rtk_outage"):
    """The receiver(s) send nothing at all (a cut antenna cable, a receiver
    rebooting): no fixes, no compass heading."""

    antenna: Antenna | None = None
    """The antenna whose receiver fails, 1 or 2; none: both."""

    def detail(self) -> str:
        return _antennas(self.antenna)


class RtkFloat(_Window, frozen=True, kw_only=True, tag="rtk_float"):
    """The receiver(s) cannot resolve ambiguities: RTK float (GGA quality 5) with the
    RTK model's float noise (decimetres) and its GST sigma."""

    antenna: Antenna | None = None
    """The antenna whose receiver floats, 1 or 2; none: both."""

    def detail(self) -> str:
        return _antennas(self.antenna)


class Multipath(_Window, frozen=True, kw_only=True, tag="multipath"):
    """A lying receiver: an antenna's positions jump while it still reports its usual fix
    quality and sigma."""

    antenna: Antenna
    """The antenna that lies, 1 or 2."""
    offset_m: tuple[Finite, Finite]
    """The jump ``[east, north]`` in the local ENU plane (m)."""

    def detail(self) -> str:
        return f"antenna {self.antenna}, offset ({self.offset_m[0]:g}, {self.offset_m[1]:g}) m"


class OdometryFreeze(_Window, frozen=True, kw_only=True, tag="odometry_freeze"):
    """The wheel encoders stop counting."""

    mode: Literal["zero", "silent"] = "zero"
    """``zero``: the encoder readings keep coming at their rate but say the wheels stand
    still (a stuck counter or a slipped encoder coupling, what a Husky's motor
    controller reports then; the harder case, since nothing looks missing);
    ``silent``: no readings at all (the link to the motor controller is down)."""

    def detail(self) -> str:
        return f"encoders {self.mode}"


class TransientObstacle(_Window, frozen=True, kw_only=True, tag="obstacle"):
    """A box standing on the ground while the fault is on: a person or an animal
    passing. The 2D lidar sees it; FARO scans do not (a scan is taken standing still,
    after it has gone)."""

    x: Coordinate
    """The box's centre's x in the field frame (m)."""
    y: Coordinate
    """The box's centre's y in the field frame (m)."""
    size_x: Positive = 0.4
    """The box along x (m)."""
    size_y: Positive = 0.4
    """The box along y (m)."""
    height: Positive = 1.0
    """The box's height (m)."""

    def box(self) -> BoxObstacle:
        return BoxObstacle(
            x=self.x, y=self.y, size_x=self.size_x, size_y=self.size_y, height=self.height
        )

    def detail(self) -> str:
        return f"box {self.size_x:g} x {self.size_y:g} m at ({self.x:g}, {self.y:g})"


Fault = RtkOutage | RtkFloat | Multipath | OdometryFreeze | TransientObstacle


class Effects(msgspec.Struct, frozen=True, kw_only=True):
    """What the active faults do to the devices: per antenna (index 0 is antenna 1)
    whether it sends nothing, is forced to RTK float, and its (east, north) offset in
    metres; what the encoders report; the obstacles the lidar sees besides the world's."""

    outage: tuple[bool, bool] = (False, False)
    force_float: tuple[bool, bool] = (False, False)
    offset: tuple[tuple[float, float], tuple[float, float]] = ((0.0, 0.0), (0.0, 0.0))
    encoders: Encoders = "ok"
    obstacles: tuple[BoxObstacle, ...] = ()


NONE = Effects()


def _per_antenna(antenna: Antenna | None, flags: list[bool]) -> None:
    for i in (0, 1):
        if antenna is None or antenna == i + 1:
            flags[i] = True


def effects(active: Sequence[Fault]) -> Effects:
    """The combined effect of the faults in ``active``: flags are or-ed, offsets of
    one antenna add up, ``silent`` encoders win over ``zero``."""
    if not active:
        return NONE
    outage, flt = [False, False], [False, False]
    off = [[0.0, 0.0], [0.0, 0.0]]
    enc: Encoders = "ok"
    boxes: list[BoxObstacle] = []
    for f in active:
        match f:
            case RtkOutage(antenna=a):
                _per_antenna(a, outage)
            case RtkFloat(antenna=a):
                _per_antenna(a, flt)
            case Multipath(antenna=a, offset_m=(e, n)):
                off[a - 1][0] += e
                off[a - 1][1] += n
            case OdometryFreeze(mode=m):
                enc = "silent" if m == "silent" or enc == "silent" else "zero"
            case TransientObstacle():
                boxes.append(f.box())
    return Effects(
        outage=(outage[0], outage[1]),
        force_float=(flt[0], flt[1]),
        offset=((off[0][0], off[0][1]), (off[1][0], off[1][1])),
        encoders=enc,
        obstacles=tuple(boxes),
    )


class FaultSchedule:
    """The configured faults against sim time. :meth:`active` and :meth:`effects` are
    pure; :meth:`changes` remembers which faults it last saw on, so each start and end
    is reported once. Not thread-safe (the simulator's step loop owns it)."""

    def __init__(self, faults: Sequence[Fault]) -> None:
        self.faults = tuple(faults)
        self._on: set[int] = set()

    def active(self, t_s: float) -> tuple[Fault, ...]:
        """The faults on at sim time ``t_s`` (seconds), in config order."""
        return tuple(f for f in self.faults if f.active(t_s))

    def effects(self, t_s: float) -> Effects:
        """What the faults on at ``t_s`` do (:data:`NONE` when none is)."""
        return effects(self.active(t_s)) if self.faults else NONE

    def changes(self, t_s: float) -> list[tuple[Fault, bool]]:
        """Faults that started (True) or ended (False) since the previous call, in
        config order. A fault whose whole window fell between two calls is reported
        neither way: it never acted on a device."""
        now = {i for i, f in enumerate(self.faults) if f.active(t_s)}
        out = [(self.faults[i], i in now) for i in sorted(now ^ self._on)]
        self._on = now
        return out


def describe(fault: Fault, started: bool) -> str:
    """One log line: ``fault rtk_outage: start (20 s) both antennas`` / ``... end``."""
    kind = fault.__struct_config__.tag
    if not started:
        return f"fault {kind}: end"
    detail = fault.detail()
    return f"fault {kind}: start ({fault.for_s:g} s)" + (f" {detail}" if detail else "")
