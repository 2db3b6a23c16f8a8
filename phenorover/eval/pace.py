"""A survey's pace and the poses its scans were placed with, from its mission log.

- Field time per location, excluding the scans: (mission done - mission created -
  the time spent scanning) / locations scanned, in the mission service's clock (the
  simulator's, in simulation), so it is the robot's time, not the machine's.
- Its physical reference: the planned route at a cruise speed, each change of
  heading as a turn in place at the robot's turn rate (accelerating and braking at
  its turn acceleration), and a settle per location that the scanner needs (the
  mission's ``settle_s``), per location. Braking and starting at each leg's ends are
  left out: they make the reference a floor no robot meets.
- Each done scan's placed pose (``pose_*``, the navigation estimate the scan is
  registered from) against the simulator's truth of it: what a scan truly needs
  from navigation, whatever the robot's place.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

from common.geo import wrap_angle
from common.missionlog import LogData, read_log
from phenorover.eval.register.truth import find_truth

NS = 1e9


@dataclasses.dataclass(frozen=True)
class Pace:
    """A survey's field time and its reference, seconds per location scanned."""

    locations: int
    field_s: float  # per location, the scans excluded
    reference_s: float  # per location: the route, the turns, the settles
    route_m: float
    turns_rad: float
    scanning_s: float  # the scans themselves, per location

    @property
    def ratio(self) -> float:
        return self.field_s / self.reference_s if self.reference_s > 0 else math.inf


def _done_ns(log: LogData) -> int | None:
    """When the mission said it was done (its event), None when it never did."""
    for stamp, _level, text in log.events:
        if text.startswith("mission ") and text.endswith(" done"):
            return stamp
    return None


def turn_time(angle: float, rate: float, accel: float) -> float:
    """Seconds to turn ``angle`` rad in place from rest to rest at ``rate`` rad/s and
    ``accel`` rad/s^2 (a triangular profile when the turn is too short to reach it)."""
    a = abs(angle)
    if a <= rate * rate / accel:
        return 2.0 * math.sqrt(a / accel)
    return a / rate + rate / accel


def _route(plan: dict[str, object]) -> tuple[float, list[float]]:
    """The plan's route length (m) and each change of heading along it (rad)."""
    legs = plan.get("legs") or []
    assert isinstance(legs, list)
    length, turns, heading = 0.0, [], None
    for lg in legs:
        dx, dy = lg["x1"] - lg["x0"], lg["y1"] - lg["y0"]
        d = math.hypot(dx, dy)
        length += d
        if d > 1e-9:
            h = math.atan2(dy, dx)
            if heading is not None:
                turns.append(abs(wrap_angle(h - heading)))
            heading = h
        if lg.get("final_yaw") is not None and heading is not None:
            turns.append(abs(wrap_angle(lg["final_yaw"] - heading)))
            heading = lg["final_yaw"]
    return length, turns


def pace(
    run_dir: Path, speed: float, turn_rate: float, turn_accel: float, settle_s: float
) -> Pace | None:
    """The pace of the survey in ``run_dir`` (see the module); None when its mission
    never finished or scanned nothing. Raises MissionLogError for a bad log."""
    log = read_log(run_dir / "mission.db")
    done = _done_ns(log)
    scans = [s for s in log.steps if s.status == "done" and s.started_ns and s.ended_ns]
    if log.mission is None or done is None or not scans:
        return None
    scanning = sum((s.ended_ns or 0) - (s.started_ns or 0) for s in scans) / NS
    field = (done - int(log.mission["created_ns"])) / NS - scanning
    length, turns = _route(json.loads(log.mission["plan_json"]))
    reference = (
        length / speed
        + sum(turn_time(a, turn_rate, turn_accel) for a in turns)
        + settle_s * len(scans)
    )
    n = len(scans)
    return Pace(n, field / n, reference / n, length, sum(turns), scanning / n)


def scan_pose_errors(run_dir: Path) -> list[tuple[float, float]]:
    """Per done scan with a truth: the placed pose's horizontal error (cm) and its
    heading error (deg) against the truth. Raises MissionLogError, TruthError."""
    out = []
    for s in read_log(run_dir / "mission.db").steps:
        if s.status != "done" or not s.file or s.pose_x is None or s.pose_y is None:
            continue
        truth = find_truth(s.file)
        if truth is None or s.pose_yaw is None:
            continue
        horizontal = 100.0 * math.hypot(s.pose_x - truth.x, s.pose_y - truth.y)
        out.append((horizontal, math.degrees(wrap_angle(s.pose_yaw - truth.yaw))))
    return out


def true_stops_cm(run_dir: Path) -> list[float]:
    """For each scan done: how far the robot truly stood (base_link, from the scan's
    truth file) from its planned location, cm. The mission's arrival tolerance
    judges this on the real robot; only the simulator can measure it."""
    out = []
    for step in read_log(run_dir / "mission.db").steps:
        truth = find_truth(step.file) if step.status == "done" and step.file else None
        if truth is not None:
            out.append(100.0 * math.hypot(truth.x - step.x, truth.y - step.y))
    return out
