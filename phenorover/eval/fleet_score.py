"""A simulated survey of several robots (:mod:`phenorover.eval.fleet`) judged by the
truth of the robots' positions and by their mission logs alone: the field time, the
instants two robots' bodies reached one segment of the lanes the survey drives
(:mod:`common.lanes`), and the locations scanned other than exactly once."""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path

import numpy as np

from common.clock import NS
from common.field import load_field
from common.lanes import LaneMap, footprint_radius, plan_lanes
from common.missionlog import read_log
from common.robot import load_robot
from phenorover.eval.fleet import Outcome


@dataclasses.dataclass(frozen=True)
class Score:
    field_s: float  # first start to last end, sim time
    conflicts: int  # truth samples with two robots in one lane segment
    closest_m: float  # the closest two robots came, true positions
    missing: list[int]  # locations no robot scanned
    twice: list[int]  # locations scanned more than once
    per_robot: dict[str, int]  # locations each robot scanned
    examples: list[str]


def score(outcome: Outcome, field: Path, robot: str = "") -> Score:
    """The outcome against the truth and the mission logs (see the module docstring);
    ``robot``: the robot description (its footprint). ValueError, one line, for a
    robot whose mission log has no end."""
    _, fld = load_field(field)
    fp = load_robot(robot).footprint
    reach = footprint_radius(fp.length, fp.width)
    lanes = plan_lanes(fld, outcome.plan)  # the lanes the survey drives
    created, done = [], []
    scanned: Counter[int] = Counter()
    per_robot = {}
    for name, run_dir in outcome.run_dirs.items():
        log = read_log(run_dir / "mission.db")
        assert log.mission is not None
        created.append(int(log.mission["created_ns"]))
        ends = [
            t
            for t, _lvl, text in log.events
            if text.startswith("mission ") and text.endswith(" done")
        ]
        if not ends:  # a survey that did not end has no field time
            raise ValueError(f"{name}: no 'mission ... done' in {run_dir / 'mission.db'}")
        done.append(max(ends))
        ids = [s.cand_id for s in log.steps if s.status == "done"]
        scanned.update(ids)
        per_robot[name] = len(ids)
    field_s = (max(done) - min(created)) / NS if done else float("nan")
    selected = outcome.plan.selected
    conflicts, closest, examples = _conflicts(outcome.truth, lanes, reach)
    return Score(
        field_s=field_s,
        conflicts=conflicts,
        closest_m=closest,
        missing=sorted(set(selected) - set(scanned)),
        twice=sorted(c for c, n in scanned.items() if n > 1),
        per_robot=per_robot,
        examples=examples,
    )


def _conflicts(
    truth: dict[str, list[tuple[int, float, float]]], lanes: LaneMap, reach: float
) -> tuple[int, float, list[str]]:
    """Instants (truth samples of every robot at one sim time) at which two robots'
    bodies reach one lane segment; the closest the robots came; a few examples."""
    names_ = sorted(truth)
    if len(names_) < 2:
        return 0, float("inf"), []
    per = {n: {t: (x, y) for t, x, y in truth[n]} for n in names_}
    common = sorted(set.intersection(*(set(p) for p in per.values())))
    if not common:
        return 0, float("inf"), []
    xy = {n: np.array([per[n][t] for t in common]) for n in names_}
    inside = {n: lanes.distances(xy[n]) <= reach for n in names_}
    count, closest, examples = 0, float("inf"), []
    for i, a in enumerate(names_):
        for b in names_[i + 1 :]:
            both = (inside[a] & inside[b]).any(axis=1)
            count += int(both.sum())
            closest = min(closest, float(np.hypot(*(xy[a] - xy[b]).T).min()))
            for k in np.flatnonzero(both)[:3]:
                seg = lanes.ids[int(np.flatnonzero(inside[a][k] & inside[b][k])[0])]
                examples.append(f"{a} and {b} in {seg} at {common[k] / NS:.1f} s")
    return count, closest, examples
