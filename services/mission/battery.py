"""The survey's battery: before each location, whether the charge the base reports
covers the drive there, the time there and the drive back to the Origin
(:func:`common.battery.must_swap`); if it does not, the robot drives to the Origin,
waits there for a swap and comes back along the plan's round trip to the location.

The model's figure for a location is scaled by the most any location has so far drawn
against it (the battery's own reports before and after), so a survey slower than the
plan's pace swaps earlier than the plan foretold, never later. Each step is a mission
event, so the mission log holds every swap. A base that reports no battery state (or
a plan from before the round trips were planned) leaves the battery unwatched, said
once.
"""

from __future__ import annotations

import math
from typing import Protocol

from common.battery import Battery, must_swap, visit_wh
from common.clock import NS
from common.messages.mission import MissionPhase
from common.messages.nav import legs_length, round_trip_halves
from common.messages.plan import PlanResult
from common.missionlog import Step
from services.mission.config import MissionConfig
from services.mission.plan import Segment
from services.mission.survey import Survey


class Host(Protocol):
    phase: MissionPhase

    def event(self, level: str, text: str) -> None: ...


class BatteryWatch:
    def __init__(
        self, host: Host, sv: Survey, cfg: MissionConfig, plan: PlanResult, battery: Battery
    ) -> None:
        self.host, self.sv, self.cfg, self.plan, self.spec = host, sv, cfg, plan, battery
        self.ratio: float | None = None  # drawn / modelled, the most so far
        self.swaps = 0
        self._visit: tuple[float, float] | None = None  # (charge at its start, model Wh)
        self._unwatched = ""
        self._since = sv.now()  # a base silent this long after it is not watched

    def _charge_wh(self) -> float | None:
        """The charge the base reports (Wh), or None when it reports none lately."""
        b = self.sv.battery.get()
        now = self.sv.now()
        if b is None or now - b.stamp_ns > self.cfg.battery_stale_s * NS:
            return None
        return b.percentage * self.spec.capacity_wh

    def _unwatch(self, why: str) -> None:
        if why != self._unwatched:
            self.host.event("warning", f"battery not watched: {why}")
            self._unwatched = why

    def before(self, step: Step, seg: Segment) -> Segment:
        """The way to ``step``'s location: ``seg``, or after a swap the plan's way from
        the Origin. Raises Aborted while waiting, as every wait does."""
        via = self.plan.via_origin
        if via is None or step.cand_id not in via:
            self._unwatch("the plan has no ways to the Origin (planned before they were)")
            return seg
        charge = self._charge_wh()
        if charge is None:
            # the first report may still be on its way when a survey begins
            if self.sv.now() - self._since >= self.cfg.battery_stale_s * NS:
                self._unwatch(f"no battery state from the base for {self.cfg.battery_stale_s:g} s")
            return seg
        self._unwatched = ""
        self._learn(charge)
        there, back = round_trip_halves(via[step.cand_id])
        at_origin = self._at_origin()
        to_m = legs_length(there) if at_origin else legs_length(seg.legs)
        pace, ratio = self.plan.options.pace, self.ratio or 1.0
        args = (self.spec, pace, to_m, pace.location_s, legs_length(back), ratio)
        if must_swap(charge, *args):
            if not at_origin:
                self._go_home(charge)
                at_origin = True
                charge = self._charge_wh() or charge  # what the way home left
            charge = self._swap(charge)
            to_m = legs_length(there)
            if must_swap(charge, self.spec, pace, to_m, pace.location_s, legs_length(back), ratio):
                self.host.event(
                    "warning",
                    f"scan {step.scan_id}: a full battery does not cover it above the "
                    "reserve; going all the same",
                )
        model = visit_wh(self.spec, pace, to_m, pace.location_s, 0.0)
        self._visit = (charge, model)
        return Segment(step.cand_id, there) if at_origin else seg

    def _learn(self, charge: float) -> None:
        """What the last location drew against the model's figure for it."""
        if self._visit is not None:
            start, model = self._visit
            drawn = start - charge
            if drawn > 0 and model > 0:
                self.ratio = max(self.ratio or 0.0, drawn / model)
        self._visit = None

    def _at_origin(self) -> bool:
        p = self.sv.pose.get()
        ox, oy = self.plan.origin
        return p is not None and math.hypot(p.x - ox, p.y - oy) <= self.cfg.origin_radius_m

    def _nearest(self) -> int:
        """The planned location nearest the robot: the way home starts there."""
        via = self.plan.via_origin
        assert via is not None
        p = self.sv.pose.get()
        x, y = (p.x, p.y) if p is not None else self.plan.origin

        def off(cand: int) -> float:
            end = round_trip_halves(via[cand])[0][-1]
            return math.hypot(end.x1 - x, end.y1 - y)

        return min(via, key=off)

    def _go_home(self, charge: float) -> None:
        via = self.plan.via_origin
        assert via is not None
        home = round_trip_halves(via[self._nearest()])[1]
        self.host.event(
            "info",
            f"battery at {100 * charge / self.spec.capacity_wh:.0f} %: to the Origin for a "
            "swap (the next location and the way back would take it below the reserve)",
        )
        self.host.phase = MissionPhase.RETURNING
        self.sv.detail = "to the Origin for a battery swap"
        ok, why = self.sv.drive(Segment(None, home), f"{self.sv.mission}.swap{self.swaps + 1}")
        if not ok:
            self.host.event("error", f"to the Origin for a battery swap: {why}")

    def _swap(self, charge: float) -> float:
        """Wait at the Origin until the base reports a swapped battery; its charge."""
        full = self.spec.capacity_wh
        self.host.phase = MissionPhase.SWAPPING
        self.sv.detail = "waiting for a battery swap"
        self.host.event(
            "info", f"at the Origin, waiting for a battery swap ({100 * charge / full:.0f} %)"
        )
        # no deadline: a swap waits for a person, as a pause does; an abort or a stop
        # ends the wait (sv.wait raises Aborted), and the dashboard shows the phase
        while (now := self._charge_wh()) is None or now < self.cfg.swapped_at * full:
            self.sv.wait(1.0)
        self.swaps += 1
        self._visit = None
        self.host.event(
            "info", f"battery swap {self.swaps} done: {100 * now / full:.0f} %, resuming"
        )
        return now
