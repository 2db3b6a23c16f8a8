"""Two robots survey one field in simulation, each in its namespace with its share of
the plan, keeping out of each other's lane segments; robot 1's mission supervisor
is killed mid-survey and its launcher starts it again. Judged by the truth of both
robots' positions and by the mission logs (phenorover/eval/fleet.py)."""

from __future__ import annotations

from pathlib import Path

from common.battery import Pace
from common.messages.mission import MissionPhase
from common.messages.plan import PlanOptions
from phenorover.eval import fleet, fleet_score
from tests.conftest import REPO

TINY = REPO / "tests" / "data" / "tiny.toml"


def test_two_robots_share_the_tiny_field_and_a_killed_supervisor_changes_nothing(
    tmp_path: Path,
) -> None:
    # scans of 20 s, not the FARO's minute: what is shared is the lanes, while driving
    options = PlanOptions(tour_time_limit_s=1.0, pace=Pace(speed=0.3, location_s=60.0))
    kill = fleet.Faults(kill=("rover1", 20.0))  # sim seconds: on its way to its first scan
    out = fleet.run(TINY, tmp_path, 2, options, rtf=10.0, faults=kill, timeout_s=600, scan_s=20.0)
    assert out.notes and "killed" in out.notes[0], out.notes
    for name, state in out.final.items():
        assert state is not None and state.phase == MissionPhase.DONE, (name, state)
    s = fleet_score.score(out, TINY)
    assert s.missing == [] and s.twice == [], s
    assert all(n >= 1 for n in s.per_robot.values()), s.per_robot  # both took a share
    assert s.conflicts == 0, s.examples
