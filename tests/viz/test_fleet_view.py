"""Several robots on one dashboard: each one's pose, route and mission under its own
namespace, the field drawn once."""

from __future__ import annotations

from typing import cast

import pytest

from common import keys
from common.messages.mission import MissionEvent, MissionPhase, MissionState
from common.messages.nav import PoseEstimate
from common.messages.plan import PlanResult
from common.robot import default_robot
from common.transport import Bus
from services.viz.fleet_view import FleetView
from services.viz.scene import Entry
from tests.conftest import FakeBus


@pytest.fixture
def split(engr_split: PlanResult) -> PlanResult:
    return engr_split


def test_each_robot_is_drawn_under_its_namespace(split: PlanResult) -> None:
    bus = FakeBus()
    logged: list[Entry] = []
    static: list[Entry] = []

    def log(_t: int, entries: list[Entry]) -> None:
        logged.extend(entries)

    view = FleetView(cast(Bus, bus), ["r1", "r2"], default_robot(), log, static.extend)
    # nothing of the robot surveying alone (the plain keys) is listened to, and no
    # robot's truth (the evaluation draws it: phenorover.eval.truth_view)
    assert keys.NAV_POSE.key not in bus.subs
    assert not [k for k in bus.subs if "sim/" in k]
    for k, ns in enumerate(("r1", "r2"), start=1):
        bus.subs[keys.MISSION_PLAN.within(ns).key](split.share_of(k))
        bus.subs[keys.NAV_POSE.within(ns).key](PoseEstimate(stamp_ns=1, x=float(k), y=2.0, yaw=0.0))
        state = MissionState(mission=f"m{k}", phase=MissionPhase.DRIVING, scans_total=5)
        bus.subs[keys.MISSION_STATE.within(ns).key](state)
        event = MissionEvent(mission=f"m{k}", level="info", text="hi")
        bus.subs[keys.MISSION_EVENT.within(ns).key](event)
    view.tick()
    paths = {e.path for e in logged}
    for ns in ("r1", "r2"):
        assert {f"fleet/{ns}/estimate", f"fleet/{ns}/log"} <= paths
        assert f"fleet/{ns}/scans_done" in paths
    drawn = [e.path for e in static]
    assert drawn.count("field/plots") == 1  # once, whoever's plan came first
    for ns in ("r1", "r2"):
        assert {f"fleet/{ns}/route", f"fleet/{ns}/locations"} <= set(drawn)
    # each share's locations, together every location of the plan
    labels = [
        int(x)
        for e in static
        if e.path.endswith("/locations")
        for x in e.item.labels.pa_array.to_pylist()
    ]
    assert sorted(labels) == sorted(split.selected)
