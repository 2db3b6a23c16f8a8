"""Each location's round trip from the Origin, and the survey's time with its swaps."""

from __future__ import annotations

import msgspec
import pytest

from common.battery import Battery, Pace
from common.field import load_field
from common.messages.nav import legs_length, round_trip_halves
from common.messages.plan import PlanOptions, PlanResult
from services.planner.core import plan


def test_round_trips_leave_from_and_return_to_the_origin_along_the_lanes() -> None:
    layout, fld = load_field("engr")
    r = plan(layout, field=fld)
    assert r.via_origin is not None and sorted(r.via_origin) == sorted(r.selected)
    ox, oy = r.origin
    by_id = {c.id: c for c in r.candidates}
    for cid, legs in r.via_origin.items():
        there, back = round_trip_halves(legs)
        assert (there[0].x0, there[0].y0) == pytest.approx((ox, oy))
        assert (back[-1].x1, back[-1].y1) == pytest.approx((ox, oy))
        assert there[-1].scan_id == cid and all(g.scan_id is None for g in back)
        assert (there[-1].x1, there[-1].y1) == pytest.approx((by_id[cid].x, by_id[cid].y))
        # every leg along a lane: axis-parallel in ENGR's frame
        assert all(g.x0 == g.x1 or g.y0 == g.y1 for g in legs)
        assert legs_length(there) == pytest.approx(legs_length(back))
    # the plan, written and read back as plan.json, keeps them
    back_again = msgspec.json.decode(msgspec.json.encode(r), type=PlanResult)
    assert back_again.via_origin == r.via_origin and back_again.survey == r.survey


def test_the_survey_estimate_counts_the_swaps_a_small_battery_needs() -> None:
    layout, fld = load_field("engr")
    pace = Pace(speed=0.3, location_s=300.0)
    full = plan(layout, field=fld, options=PlanOptions(pace=pace))
    assert full.survey is not None and full.survey.swaps == 0
    assert full.survey.drive_m == pytest.approx(full.tour.length)
    n = len(full.selected)
    assert full.survey.time_s == pytest.approx(full.tour.length / 0.3 + n * 300.0)
    small = plan(layout, field=fld, options=PlanOptions(pace=pace), battery=Battery(capacity_wh=60))
    assert small.survey is not None and small.survey.swaps >= 2 and small.survey.feasible
    assert small.survey.time_s > full.survey.time_s + small.survey.swaps * 600.0
