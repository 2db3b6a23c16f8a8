"""A field's lanes cut into the segments robots reserve."""

from __future__ import annotations

import numpy as np
import pytest

from common.field import load_field
from common.lanes import (
    HOME_STRIDE,
    PARK_M,
    LaneMap,
    central_cross_lane,
    driven_rows,
    footprint_radius,
    homes,
)
from common.messages.nav import Leg


@pytest.fixture(scope="module")
def engr() -> LaneMap:
    _, fld = load_field("engr")
    return LaneMap(fld)


def test_every_lane_is_cut_between_neighbouring_intersections(engr: LaneMap) -> None:
    _, fld = load_field("engr")
    nx, ny = len(fld.cross_lanes_x), len(fld.row_lanes_y)
    assert len(engr.ids) == nx * (ny - 1) + ny * (nx - 1)
    assert len(set(engr.ids)) == len(engr.ids)


def test_a_robot_at_an_intersection_is_in_every_segment_meeting_there(engr: LaneMap) -> None:
    _, fld = load_field("engr")
    x, y = fld.cross_lanes_x[0], fld.row_lanes_y[0]  # a corner: two segments meet
    r = footprint_radius(0.99, 0.67)
    assert engr.at(np.array([[x, y]]), r) == [{"c0.0", "r0.0"}]
    mid = 0.5 * (fld.row_lanes_y[1] + fld.row_lanes_y[2])  # halfway along cross lane 2
    assert engr.at(np.array([[fld.cross_lanes_x[2], mid]]), r) == [{"c2.1"}]
    inner = engr.at(np.array([[fld.cross_lanes_x[2], fld.row_lanes_y[1]]]), r)
    assert inner == [{"c2.0", "c2.1", "r1.1", "r1.2"}]
    # the distance to a centre line is the perpendicular one
    d = engr.distances(np.array([[fld.cross_lanes_x[2] + 0.3, mid]]))
    assert d[0, engr.ids.index("c2.1")] == pytest.approx(0.3)


def test_a_leg_along_a_cross_lane_passes_its_segments_and_the_ends(engr: LaneMap) -> None:
    _, fld = load_field("engr")
    x, ys = float(fld.cross_lanes_x[3]), fld.row_lanes_y
    leg = Leg(x0=x, y0=float(ys[0]), x1=x, y1=float(ys[2]))
    got = engr.along([leg], 0.6)
    # the lane's first two segments, the next one meeting at its end, and on either
    # side of the lane the row-gap lanes' at each intersection passed
    assert got == {"c3.0", "c3.1", "c3.2"} | {f"r{j}.{k}" for j in (0, 1, 2) for k in (2, 3)}
    assert engr.along([], 0.6) == set()


def test_only_the_lanes_a_survey_drives_are_cut() -> None:
    _, fld = load_field("engr")
    nx, ny = len(fld.cross_lanes_x), len(fld.row_lanes_y)
    assert driven_rows("aha", ny) == [0, ny - 1]
    assert driven_rows("br", ny) == list(range(ny))
    assert driven_rows("lanes", ny, [2, 0, 2]) == [0, 2]
    aha = LaneMap(fld, driven_rows("aha", ny))
    assert len(aha.ids) == nx * (ny - 1) + 2 * (nx - 1)
    # two robots at the ends of a row gap, in neighbouring alleys: in no common segment
    ends = np.array(
        [[fld.cross_lanes_x[2], fld.row_lanes_y[1]], [fld.cross_lanes_x[3], fld.row_lanes_y[1]]]
    )
    a, b = aha.at(ends, footprint_radius(0.99, 0.67))
    assert a and b and not a & b


def test_robots_park_by_the_locations_when_the_plan_asks() -> None:
    xs = np.arange(10, dtype=np.float64) * 4.5
    ys = np.array([1.0, 2.8, 4.6, 6.4])
    origin = np.array([xs[-1], ys[0]])
    pts = np.array([[xs[3], 2.8], [xs[4], 4.6], [xs[4], 6.4], [xs[8], 2.8]])
    assert central_cross_lane(xs, pts) == 4  # the median's lane
    access, home = homes(xs, ys, origin, 2, near=pts)
    # the two edge lanes, at the cross lane nearest the locations, not the Origin's
    assert access.tolist() == [[xs[4], ys[0]], [xs[4], ys[-1]]]
    assert home[:, 1].tolist() == pytest.approx([ys[0] - PARK_M, ys[-1] + PARK_M])
    # more robots: HOME_STRIDE cross lanes apart around it, then where there is room
    access, _ = homes(xs, ys, origin, 4, near=pts)
    assert (access[:, 0] / 4.5).round().tolist() == [4, 4, 4 + HOME_STRIDE, 4 + HOME_STRIDE]
    edge = np.array([[xs[0], 2.8]] * 3)
    access, _ = homes(xs, ys, origin, 6, near=edge)
    assert sorted((access[:, 0] / 4.5).round().astype(int).tolist()) == [0, 0, 2, 2, 4, 4]
    # without: from the Origin's corner inwards
    access, _ = homes(xs, ys, origin, 2)
    assert access[:, 0].tolist() == [xs[-1], xs[-1]]
    with pytest.raises(ValueError, match="12 robots park 2 cross lanes apart"):
        homes(xs, ys, origin, 12, near=pts)
