"""The robot's battery: the stated discharge model, and when a survey must leave for a
battery swap. Pure; the planner's time estimate and the mission's decisions both come
from :func:`must_swap`, so the plan foretells the swaps the mission makes.

The discharge model (a robot description's ``[battery]``, :class:`Battery`): the robot
draws ``standby_w + payload_w`` at all times and ``drive_w`` more while its wheels
turn; the charge falls linearly with the energy drawn (coulomb counting at a constant
voltage). A survey stops for a swap at a safe place, the field's Origin, before the
charge would fall below ``reserve``: each location is begun only when the charge
covers the drive to it, the time there and the drive from it back to the Origin, with
``MARGIN`` to spare.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Annotated

import msgspec

from common.messages.core import NonNegative

Energy = Annotated[float, msgspec.Meta(gt=0.0, le=1e6)]  # Wh
Power = Annotated[float, msgspec.Meta(ge=0.0, le=1e5)]  # W
Seconds = Annotated[float, msgspec.Meta(ge=0.0, le=1e6)]
Fraction = Annotated[float, msgspec.Meta(ge=0.0, lt=1.0)]

# what a prediction is multiplied by before it is held against the charge: positioning
# takes longer at some locations than at others, and a route's turns are slower than
# its straights
MARGIN = 1.25


class Battery(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A robot's battery and what it draws (:attr:`common.robot.Robot.battery`). The
    defaults are the Husky A200's (``common/robots/husky.toml`` says where each comes
    from)."""

    capacity_wh: Energy = 480.0
    """The energy of a full battery (Wh)."""
    standby_w: Power = 60.0
    """The draw of the platform standing, powered (W)."""
    payload_w: Power = 40.0
    """The draw of what it carries: computers, receivers, the scanner (W)."""
    drive_w: Power = 100.0
    """The draw on top while the wheels turn (W)."""
    reserve: Fraction = 0.2
    """The fraction of the capacity never to be used: the charge a swap must come
    before."""
    swap_s: Seconds = 600.0
    """How long a swap takes once the robot waits at the Origin (s)."""
    voltage_v: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0)] = 24.0
    """The pack's nominal voltage (V): the model counts charge at a constant voltage."""

    def power_w(self, moving: bool) -> float:
        """What the robot draws (W), its wheels turning or not."""
        return self.standby_w + self.payload_w + (self.drive_w if moving else 0.0)

    @property
    def reserve_wh(self) -> float:
        return self.reserve * self.capacity_wh

    def describe(self) -> str:
        """The model in one line, printed beside every figure that rests on it."""
        return (
            f"battery {self.capacity_wh:g} Wh, {self.standby_w + self.payload_w:g} W standing "
            f"+ {self.drive_w:g} W driving, reserve {100 * self.reserve:g} %, "
            f"swap {self.swap_s:g} s"
        )


class Pace(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How fast a survey goes, for its estimates."""

    speed: Annotated[float, msgspec.Meta(gt=0.0, le=10.0)] = 0.3
    """The mean speed along a route, turns included (m/s)."""
    location_s: Seconds = 300.0
    """The time at each location: positioning, settling and the scan (s)."""

    def drive_s(self, metres: float) -> float:
        return metres / self.speed


def visit_wh(battery: Battery, pace: Pace, to_m: float, at_s: float, home_m: float) -> float:
    """The energy (Wh) of a location begun now: the drive of ``to_m`` to it, ``at_s``
    there and the drive of ``home_m`` from it back to the Origin."""
    moving = battery.power_w(True) * pace.drive_s(to_m + home_m)
    return (moving + battery.power_w(False) * at_s) / 3600.0


def must_swap(
    charge_wh: float,
    battery: Battery,
    pace: Pace,
    to_m: float,
    at_s: float,
    home_m: float,
    ratio: float = 1.0,
) -> bool:
    """Whether a location must wait for a swap: with ``charge_wh`` left, the visit
    (:func:`visit_wh` times ``ratio``, what the survey has so far drawn against the
    model's figure, and times ``MARGIN``) would end with less than the reserve."""
    need = MARGIN * ratio * visit_wh(battery, pace, to_m, at_s, home_m)
    return charge_wh - need < battery.reserve_wh


@dataclasses.dataclass(frozen=True)
class Visit:
    """One location of a tour: ``to_m`` the drive to it from the previous one (or from
    where the tour starts, first), ``from_origin_m`` and ``home_m`` its drives from and
    to the Origin, where batteries are swapped (m)."""

    to_m: float
    from_origin_m: float
    home_m: float


class Estimate(msgspec.Struct, frozen=True, kw_only=True):
    """A survey's time and energy, the swaps included: ``time_s`` from leaving where
    the tour starts (the Origin, or a fleet robot's home) to being back;
    ``swaps_before``: the tour positions (0-based) of the locations a swap comes
    before; ``drive_m``: metres driven, detours for the swaps included; ``energy_wh``:
    drawn in all; ``feasible``: every location fits in one full battery (else the
    survey would run below its reserve)."""

    time_s: NonNegative
    drive_m: NonNegative
    energy_wh: NonNegative
    swaps_before: list[int]
    feasible: bool
    battery: str

    @property
    def swaps(self) -> int:
        return len(self.swaps_before)


def estimate(visits: Sequence[Visit], end_m: float, battery: Battery, pace: Pace) -> Estimate:
    """The survey of ``visits`` in order, then ``end_m`` back to where the legs end,
    starting with a full battery where they start (the Origin, or a fleet robot's home)
    and swapping, at the Origin, where the mission would (:func:`must_swap`)."""
    full = battery.capacity_wh
    charge, time_s, drive_m, energy = full, 0.0, 0.0, 0.0
    swaps: list[int] = []
    feasible = True
    home_m = 0.0  # the robot starts with a full battery, nothing to go back for
    at_origin = True

    def spend(metres: float, standing_s: float) -> None:
        nonlocal charge, time_s, drive_m, energy
        wh = visit_wh(battery, pace, metres, standing_s, 0.0)
        charge -= wh
        energy += wh
        drive_m += metres
        time_s += pace.drive_s(metres) + standing_s

    for k, v in enumerate(visits):
        to_m = v.to_m  # from the previous location, or where the legs start (below: a swap)
        if must_swap(charge, battery, pace, to_m, pace.location_s, v.home_m):
            if not at_origin:
                spend(home_m, 0.0)
                at_origin, to_m = True, v.from_origin_m
            if charge < full:
                swaps.append(k)
                charge = full
                time_s += battery.swap_s
            if must_swap(charge, battery, pace, to_m, pace.location_s, v.home_m):
                feasible = False  # not even a full battery: the mission goes anyway
        spend(to_m, pace.location_s)
        at_origin, home_m = False, v.home_m
    spend(end_m if visits else 0.0, 0.0)
    return Estimate(
        time_s=time_s,
        drive_m=drive_m,
        energy_wh=energy,
        swaps_before=swaps,
        feasible=feasible,
        battery=battery.describe(),
    )
