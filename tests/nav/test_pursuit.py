from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.messages.nav import Leg
from services.nav.pursuit import aim_at, cross_track, curvature, lookahead_point, predict


def test_curvature_hand_worked() -> None:
    # point 1 m ahead and 1 m left: alpha = 45 deg, L_D = sqrt(2): k = 2 sin(45)/sqrt(2) = 1
    assert curvature(0, 0, 0, 1, 1) == pytest.approx(1.0)
    # straight ahead: no curvature; right: negative
    assert curvature(0, 0, 0, 2, 0) == pytest.approx(0.0)
    assert curvature(0, 0, 0, 1, -1) == pytest.approx(-1.0)
    # the same geometry with the robot rotated 90 deg
    assert curvature(0, 0, math.pi / 2, -1, 1) == pytest.approx(1.0)


def test_lookahead_point_on_the_line() -> None:
    # robot 0.6 m left of a path along x: the point is 0.8 m ahead (3-4-5 triangle)
    px, py = lookahead_point(0.0, 0.6, 0, 0, 10, 0, 1.0)
    assert (px, py) == pytest.approx((0.8, 0.0))
    # near the end: the end itself
    assert lookahead_point(9.8, 0.0, 0, 0, 10, 0, 1.0) == pytest.approx((10.0, 0.0))


@given(st.floats(-5, 5), st.floats(-5, 5))
def test_lookahead_point_stays_on_segment(x: float, y: float) -> None:
    px, py = lookahead_point(x, y, 0, 0, 3, 4, 1.0)
    assert abs(cross_track(px, py, 0, 0, 3, 4)) < 1e-9
    assert -1e-9 <= px <= 3 + 1e-9


def test_cross_track_sign() -> None:
    assert cross_track(1, 0.5, 0, 0, 2, 0) == pytest.approx(0.5)  # left positive
    assert cross_track(1, -0.5, 0, 0, 2, 0) == pytest.approx(-0.5)


def test_predict_carries_the_pose_along_the_arc_of_the_command() -> None:
    assert predict(1.0, 2.0, 0.0, 0.5, 0.0, 0.2) == pytest.approx((1.1, 2.0, 0.0))
    # a quarter turn of radius 1 m: the chord's end, heading turned by 90 deg
    x, y, yaw = predict(0.0, 0.0, 0.0, 1.0, 1.0, math.pi / 2)
    assert yaw == pytest.approx(math.pi / 2)
    assert math.hypot(x, y) == pytest.approx(math.pi / 2)  # the midpoint-heading step
    assert predict(1.0, 2.0, 0.3, 0.5, 0.2, 0.0) == (1.0, 2.0, 0.3)


def test_a_robot_beside_the_leg_aims_back_at_the_line() -> None:
    leg = Leg(x0=0.0, y0=0.0, x1=10.0, y1=0.0)
    assert aim_at(0.0, 0.0, leg, 0.6) == pytest.approx(0.0)
    left = aim_at(0.0, 0.08, leg, 0.6)  # 8 cm left of the line: aim right of the leg
    assert left == pytest.approx(-math.asin(0.08 / 0.6))
    # at the leg's end there is no line ahead to aim at: the leg's heading
    assert aim_at(9.9, 0.05, leg, 0.6) == pytest.approx(0.0)
