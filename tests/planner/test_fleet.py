"""Locations split between robots so that the slowest finishes first."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from common.battery import Pace
from common.field import build_field, load_field
from common.lanes import LaneMap, central_cross_lane, footprint_radius
from common.messages.plan import PlanOptions
from phenorover.cli import main
from phenorover.eval.fields import engr_sized
from services.planner.cli import fleet_rows
from services.planner.core import plan
from services.planner.fleet import check_lanes, split_tours, tour_time
from services.planner.outputs import write_all
from services.planner.route import Navigator

PACE = Pace(speed=0.5, location_s=300.0)


def line(n: int, step: float = 10.0) -> np.ndarray:
    """Distances between the Origin and ``n`` locations along one line."""
    x = np.arange(n + 1) * step
    return np.abs(x[:, None] - x[None, :])


def test_two_robots_share_the_locations_and_the_slowest_is_balanced() -> None:
    d = line(12)
    one = split_tours(d, 1, PACE)
    two = split_tours(d, 2, PACE, time_limit_s=1.0)
    visited = sorted(k for o in two.orders for k in o if k != 0)
    assert visited == list(range(1, 13))  # every location once
    assert all(o[0] == 0 for o in two.orders)
    assert one.makespan_s == pytest.approx(tour_time(d, list(range(13)), PACE))
    # twelve locations of 300 s: no robot can do better than six of them
    assert two.makespan_s >= 6 * 300.0
    assert two.makespan_s <= 0.6 * one.makespan_s
    assert abs(two.times_s[0] - two.times_s[1]) <= 300.0 + 2 * 120.0 / 0.5


def test_more_robots_than_locations_or_lanes_is_one_line() -> None:
    with pytest.raises(ValueError, match="3 robots for 2 locations"):
        split_tours(line(2), 3, PACE)
    _, fld = load_field("engr")
    nav = Navigator(fld)
    lanes = len(fld.cross_lanes_x) + len(fld.row_lanes_y)
    check_lanes(nav, lanes)
    with pytest.raises(ValueError, match=f"{lanes + 1} robots for a field of {lanes} lanes"):
        check_lanes(nav, lanes + 1)


def test_a_field_of_600_plots_for_two_robots(tmp_path: Path) -> None:
    layout = engr_sized(20, 30, "f600")
    opt = PlanOptions(
        robots=2, cover="greedy", tour_time_limit_s=2.0, pace=Pace(speed=0.3, location_s=300.0)
    )
    r = plan(layout, options=opt)
    assert r.fleet is not None and len(r.fleet.parts) == 2
    taken = sorted(i for p in r.fleet.parts for i in p.order if i != 0)
    assert taken == sorted(r.selected)
    lanes = LaneMap(build_field(layout))
    radius = footprint_radius(2 * layout.robot_half_length, 2 * layout.robot_half_width)
    for p in r.fleet.parts:
        assert [g.scan_id for g in p.legs if g.scan_id is not None] == p.order[1:-1]
        assert (p.legs[0].x0, p.legs[0].y0) == pytest.approx(p.home)
        assert (p.legs[-1].x1, p.legs[-1].y1) == pytest.approx(p.home)
        # parked off the lanes: a robot at home stands in nobody's way
        assert lanes.at(np.array([p.home]), radius + 0.5) == [set()]
    # each robot its own home: the first by the Origin, the second across the field
    one, two = (p.home for p in r.fleet.parts)
    assert one[0] == pytest.approx(r.origin[0]) and one[1] < r.origin[1]
    assert two[0] == pytest.approx(r.origin[0]) and two[1] > r.origin[1] + 10.0
    assert r.survey is not None and r.fleet.one_robot_s == r.survey.time_s
    assert r.fleet.makespan_s <= 0.6 * r.fleet.one_robot_s
    # each robot's waypoints beside the tour's
    files = write_all(r, tmp_path)
    for p in r.fleet.parts:
        rows = list(csv.DictReader(files[f"waypoints-robot{p.robot}.csv"].open()))
        assert [int(x["scan_id"]) for x in rows if x["scan_id"]] == p.order[1:-1]


def test_robots_parked_by_the_locations_drive_less_and_say_where(
    capsys: pytest.CaptureFixture[str],
) -> None:
    layout = engr_sized(8, 12, "f96")
    opts = {
        (n, home): PlanOptions(
            robots=n, home=home, cover="greedy", tour_time_limit_s=1.0, pace=Pace(speed=0.3)
        )
        for n in (1, 2)
        for home in ("origin", "near")
    }
    plans = {k: plan(layout, options=o) for k, o in opts.items()}
    alone = plans[1, "origin"]
    assert alone.fleet is None and alone.survey is not None
    fld = build_field(layout)
    pts = np.array([fld.cand_xy[list(fld.cand_ids).index(i)] for i in alone.selected])
    central = fld.cross_lanes_x[central_cross_lane(fld.cross_lanes_x, pts)]
    for n in (1, 2):
        near = plans[n, "near"].fleet
        assert near is not None and len(near.parts) == n
        assert [p.home[0] for p in near.parts] == pytest.approx([central] * n)
        for p in near.parts:  # the estimate leaves from home, not from the Origin
            assert p.survey.drive_m == pytest.approx(sum(g.length for g in p.legs))
        corner = plans[n, "origin"]
        assert near.makespan_s < (corner.fleet.makespan_s if corner.fleet else alone.survey.time_s)
    # one robot parked by its locations: a fleet of one on the shortest tour from there
    one = plans[1, "near"]
    assert one.fleet is not None and one.fleet.status == "optimal"
    assert sorted(one.fleet.parts[0].order[1:-1]) == sorted(alone.selected)
    rows = dict(fleet_rows(plans[2, "near"]))
    assert f"parked at ({central:.1f}, " in rows["robot 1"]


@pytest.mark.parametrize(
    ("flags", "where"),
    [
        (["--speed", "-1"], "$.pace.speed"),
        (["--robots", "0"], "$.robots"),
        (["--location-s", "nan"], "$.pace.location_s"),
    ],
)
def test_plan_cli_refuses_a_bad_option_in_one_line(
    flags: list[str], where: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["plan", "engr", "--out", str(tmp_path), *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and where in err[0], err
