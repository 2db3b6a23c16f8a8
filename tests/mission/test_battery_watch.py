"""The mission's battery watch on a fake survey: it lets a location go while the
charge covers it and the way home, sends the robot home and waits for a swap when it
does not, comes back along the plan's round trip, and says once when it cannot watch."""

from __future__ import annotations

import dataclasses
from typing import Any

import msgspec
import pytest

from common.battery import Battery, Pace
from common.clock import NS
from common.field import load_field
from common.messages.base import BatteryState
from common.messages.mission import MissionPhase
from common.messages.nav import PoseEstimate, round_trip_halves
from common.messages.plan import PlanOptions, PlanResult
from common.missionlog import Step
from common.streams import Latest
from services.mission.battery import BatteryWatch
from services.mission.config import MissionConfig
from services.mission.plan import Segment, segments
from services.planner.core import plan

SPEC = Battery(capacity_wh=100.0)


@pytest.fixture(scope="module")
def engr() -> PlanResult:
    layout, fld = load_field("engr")
    return plan(layout, field=fld, options=PlanOptions(pace=Pace(speed=0.3, location_s=300)))


def pose(x: float, y: float) -> PoseEstimate:
    return PoseEstimate(stamp_ns=0, x=x, y=y, yaw=0.0, v=0.0, w=0.0, localized=True)


class FakeSurvey:
    """The survey's side the watch uses: its feeds, clock, waits and drives; a swap
    arrives ``swap_waits`` waits after the robot stands at the Origin."""

    def __init__(self, origin: tuple[float, float], swap_waits: int = 3) -> None:
        self.pose: Latest[PoseEstimate] = Latest()
        self.battery: Latest[BatteryState] = Latest()
        self.t = 100 * NS
        self.mission, self.detail = "m", ""
        self.drives: list[Segment] = []
        self.origin, self.swap_waits, self.waits = origin, swap_waits, 0

    def now(self) -> int:
        return self.t

    def charge(self, fraction: float) -> None:
        self.battery.put(BatteryState(stamp_ns=self.t, percentage=fraction))

    def wait(self, seconds: float) -> int:
        self.t += int(seconds * NS)
        self.waits += 1
        if self.waits >= self.swap_waits:
            self.charge(1.0)
        return 0

    def drive(self, seg: Segment, route_id: str) -> tuple[bool, str]:
        self.drives.append(seg)
        last = seg.legs[-1]
        self.pose.put(pose(last.x1, last.y1))
        self.t += 60 * NS
        self.charge(self.battery.get().percentage - 0.01)  # type: ignore[union-attr]
        return True, ""


@dataclasses.dataclass
class FakeHost:
    phase: MissionPhase = MissionPhase.DRIVING
    events: list[tuple[str, str]] = dataclasses.field(default_factory=list)
    phases: list[MissionPhase] = dataclasses.field(default_factory=list)

    def event(self, level: str, text: str) -> None:
        self.events.append((level, text))
        self.phases.append(self.phase)


def step_of(seg: Segment, k: int) -> Step:
    x, y, yaw = seg.end
    assert seg.cand_id is not None
    return Step(k, k + 1, seg.cand_id, x, y, yaw, "pending", 0)


def watch(engr: PlanResult, **cfg: Any) -> tuple[BatteryWatch, FakeSurvey, FakeHost]:
    sv, host = FakeSurvey(engr.origin), FakeHost()
    w = BatteryWatch(host, sv, MissionConfig(**cfg), engr, SPEC)  # type: ignore[arg-type]
    return w, sv, host


def test_a_charged_battery_lets_the_location_go(engr: PlanResult) -> None:
    w, sv, host = watch(engr)
    seg = segments(engr)[1]
    prev = segments(engr)[0].legs[-1]
    sv.pose.put(pose(prev.x1, prev.y1))
    sv.charge(0.9)
    assert w.before(step_of(seg, 1), seg) is seg
    assert host.events == [] and sv.drives == []


def test_a_low_battery_goes_home_waits_for_the_swap_and_comes_back(engr: PlanResult) -> None:
    w, sv, host = watch(engr)
    segs = segments(engr)
    seg, prev = segs[3], segs[2].legs[-1]
    sv.pose.put(pose(prev.x1, prev.y1))
    sv.charge(0.3)  # 30 Wh: 10 above the reserve, less than a location of 300 s
    got = w.before(step_of(seg, 3), seg)
    assert engr.via_origin is not None
    there, _back = round_trip_halves(engr.via_origin[seg.cand_id or 0])
    home = round_trip_halves(engr.via_origin[segs[2].cand_id or 0])[1]
    assert [d.legs for d in sv.drives] == [home]  # from where it stood, home
    assert got == Segment(seg.cand_id, there)  # and back out from the Origin
    texts = [t for _, t in host.events]
    assert texts[0].startswith("battery at 30 %: to the Origin for a swap")
    assert texts[1] == "at the Origin, waiting for a battery swap (29 %)"
    assert texts[2] == "battery swap 1 done: 100 %, resuming"
    assert host.phases[1] == MissionPhase.SWAPPING and w.swaps == 1


def test_at_the_origin_a_low_battery_waits_there(engr: PlanResult) -> None:
    w, sv, host = watch(engr)
    seg = segments(engr)[0]
    sv.pose.put(pose(*engr.origin))
    sv.charge(0.25)
    got = w.before(step_of(seg, 0), seg)
    assert sv.drives == [] and got.legs[0].x0 == pytest.approx(engr.origin[0])
    assert next(t for _, t in host.events).startswith("at the Origin, waiting")


def test_without_battery_state_or_round_trips_the_battery_is_not_watched(
    engr: PlanResult,
) -> None:
    w, sv, host = watch(engr)
    seg = segments(engr)[1]
    assert w.before(step_of(seg, 1), seg) is seg
    assert host.events == []  # the first report may be on its way yet
    sv.t += 10 * NS
    assert w.before(step_of(seg, 1), seg) is seg
    assert w.before(step_of(seg, 1), seg) is seg
    assert host.events == [
        ("warning", "battery not watched: no battery state from the base for 10 s")
    ]
    # a plan from before the round trips were planned
    w2, sv2, host2 = watch(msgspec.structs.replace(engr, via_origin=None))
    sv2.charge(0.1)
    assert w2.before(step_of(seg, 1), seg) is seg
    assert "planned before they were" in host2.events[0][1]


def test_after_a_swap_that_cut_the_power_the_robot_leaves_from_the_origin(
    engr: PlanResult,
) -> None:
    """On the Husky a swap powers the computer down: the mission starts afresh with the
    robot at the Origin and a full battery, and must not join the next location's
    segment (from the last location, across the plots) but take the round trip."""
    w, sv, host = watch(engr)
    segs = segments(engr)
    seg = segs[3]
    sv.pose.put(pose(*engr.origin))
    sv.charge(1.0)
    got = w.before(step_of(seg, 3), seg)
    assert engr.via_origin is not None
    assert got == Segment(seg.cand_id, round_trip_halves(engr.via_origin[seg.cand_id or 0])[0])
    assert got.legs[0].x0 == pytest.approx(engr.origin[0]) and host.events == []
