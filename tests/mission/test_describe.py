"""The mission's one-line state: the distance driven is a measurement, the plan's
length beside it is labelled planned."""

from __future__ import annotations

from common.messages.mission import MissionPhase, MissionState
from services.mission.cli import describe


def test_the_distance_driven_is_measured_and_the_planned_length_labelled() -> None:
    s = MissionState(
        mission="engr-1",
        phase=MissionPhase.DRIVING,
        scans_done=3,
        scans_total=11,
        distance_m=52.34,
        planned_m=144.0,
    )
    assert describe(s) == (
        "engr-1: driving, 3/11 scans done, 0 failed, 52.3 m driven (measured; 144.0 m planned)"
    )


def test_without_a_plan_no_planned_length_is_claimed() -> None:
    s = MissionState(mission="", phase=MissionPhase.IDLE)
    assert describe(s) == "-: idle, 0/0 scans done, 0 failed, 0.0 m driven (measured)"
