"""Turns in place at the corners (paper section 4.3): the turn rate toward a heading,
and the small drive along the robot's heading that keeps a turning robot on the next
leg's line. Pure."""

from __future__ import annotations

import math

from services.nav.follower_config import FollowerConfig
from services.nav.pursuit import ramp

# heading errors (deg) against the leg between which the hold fades out: at 20 deg a
# drive along the heading moves the robot three times as far along the leg as across
HOLD_NONE_DEG = 20.0
HOLD_FULL_DEG = 35.0


def turn_rate(err: float, w: float, cfg: FollowerConfig, dt: float) -> float:
    """The turn rate toward a heading ``err`` rad away, from the rate ``w`` commanded
    ``dt`` s ago (see FollowerConfig)."""
    brake = math.sqrt(2.0 * cfg.turn_braking * cfg.max_turn_accel * abs(err))
    rate = max(cfg.min_turn_rate, min(cfg.max_turn_rate, cfg.rotate_gain * abs(err), brake))
    return ramp(math.copysign(rate, err), w, cfg.max_turn_accel, dt)


def line_hold(xte: float, herr: float, cfg: FollowerConfig) -> float:
    """The speed along its heading (m/s) that draws a robot turning onto a leg toward
    the leg's line, from its cross-track ``xte`` (m, left positive) and heading error
    ``herr`` (rad) against the leg. A skid-steer turning in place also slides sideways
    (uneven traction moves its rotation centre off the body centre: the paper's corner
    errors), and the stop at the corner lands centimetres past or short of it; either
    would start the leg off its line, to be closed by pure pursuit over a metre or two
    of driving. Driving along its heading moves the robot across the leg by sin(herr)
    of the way, so the hold divides by it and closes the offset at ``turn_hold_gain``
    (1/s) while the heading has a say across the leg: fully from ``HOLD_FULL_DEG``
    off the leg's heading, fading out to none at ``HOLD_NONE_DEG``, nearer to which
    it would mostly drive along the leg. Beyond ``turn_hold_max_m`` off the line (a
    robot joining a route from afar) it leaves the offset to pure pursuit."""
    a = abs(herr)
    if abs(xte) > cfg.turn_hold_max_m or a <= math.radians(HOLD_NONE_DEG):
        return 0.0
    none, full = math.radians(HOLD_NONE_DEG), math.radians(HOLD_FULL_DEG)
    share = min(1.0, (a - none) / (full - none))
    v = -share * cfg.turn_hold_gain * xte / math.sin(herr)
    return max(-cfg.turn_hold_speed, min(cfg.turn_hold_speed, v))
