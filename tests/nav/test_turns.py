"""The corner turn's hold on the next leg's line (services.nav.turns.line_hold)."""

from __future__ import annotations

import math

from services.nav.follower_config import FollowerConfig
from services.nav.turns import line_hold

CFG = FollowerConfig()


def test_the_hold_drives_toward_the_line_whichever_way_the_robot_faces() -> None:
    # a leg along +x; the robot 5 cm to its left (xte > 0), turning onto it
    for herr_deg in (90.0, 60.0, -60.0, -90.0, 150.0):
        v = line_hold(0.05, math.radians(herr_deg), CFG)
        # moving v along the heading changes the cross-track by v sin(herr)
        assert v * math.sin(math.radians(herr_deg)) < 0, herr_deg
    assert line_hold(-0.05, math.radians(90.0), CFG) > 0


def test_the_hold_closes_the_offset_at_its_gain_within_its_speed() -> None:
    v = line_hold(0.02, math.radians(90.0), CFG)
    assert math.isclose(v, -CFG.turn_hold_gain * 0.02)
    assert abs(line_hold(0.2, math.radians(90.0), CFG)) == CFG.turn_hold_speed


def test_no_hold_near_the_legs_heading_far_off_the_line_or_when_turned_off() -> None:
    assert line_hold(0.05, math.radians(10.0), CFG) == 0.0  # it would drive along the leg
    assert line_hold(CFG.turn_hold_max_m + 0.01, math.radians(90.0), CFG) == 0.0
    assert line_hold(0.05, math.radians(90.0), FollowerConfig(turn_hold_gain=0.0)) == 0.0
    # fading in between
    half = line_hold(0.01, math.radians(27.5), CFG)
    full = line_hold(0.01, math.radians(35.0), CFG)
    assert 0 < half / full < 1
