import math

import numpy as np
import pytest

from common.robot import default_robot
from services.sim.robot import (
    RobotConfig,
    RobotState,
    body_to_field,
    encoder_twist,
    settle,
    step,
)
from services.sim.terrain import TerrainConfig, build_terrain

BOUNDS = np.array([0.0, 0.0, 30.0, 20.0])
FLAT = build_terrain(BOUNDS, TerrainConfig(slope_pct=0.0, bump_rms=0.0, margin=5.0), 0)
CFG = RobotConfig()
LIM = default_robot().limits
DT = 0.02


def drive(state, v, w, seconds, rng, terrain=FLAT, soil=1.0):
    states = [state]
    for _ in range(round(seconds / DT)):
        states.append(step(states[-1], v, w, DT, terrain, rng, CFG, soil))
    return states


def test_straight_driving_respects_speed_limit():
    rng = np.random.default_rng(0)
    states = drive(RobotState(x=2.0, y=10.0), 2.0, 0.0, 6.0, rng)
    vw = np.array([s.v_wheel for s in states])
    assert vw.max() <= LIM.max_speed + 1e-12 and vw[-1] > 0.99 * LIM.max_speed
    end = states[-1]
    dist = end.x - 2.0
    # 1 m/s^2 ramp to 1 m/s, then cruise, minus 1 % slip and the motor lag
    assert 5.0 < dist < 5.5
    assert abs(end.y - 10.0) < 0.1 and abs(end.yaw) < math.radians(3)


def test_acceleration_limits():
    rng = np.random.default_rng(1)
    states = drive(RobotState(x=5.0, y=5.0), 1.0, 0.0, 1.0, rng)
    states += drive(states[-1], -1.0, 2.0, 2.0, rng)[1:]
    vw = np.array([s.v_wheel for s in states])
    ww = np.array([s.w_wheel for s in states])
    assert np.abs(np.diff(vw)).max() <= LIM.max_accel * DT + 1e-12
    assert np.abs(np.diff(ww)).max() <= LIM.max_turn_accel * DT + 1e-12
    assert np.abs(ww).max() <= LIM.max_turn_rate + 1e-12


def test_in_place_rotation_under_rotates_and_drifts():
    rng = np.random.default_rng(2)
    start = RobotState(x=15.0, y=10.0)
    states = drive(start, 0.0, 1.0, 4.0, rng, soil=2.0)
    true_turn = np.unwrap([s.yaw for s in states])[-1]
    enc_turn = sum(encoder_twist(s, rng, CFG)[1] * DT for s in states[1:])
    # the wheels (and so the encoders) say more rotation than the body made
    assert true_turn < 0.92 * enc_turn
    assert true_turn > 0.5 * enc_turn
    drift = math.hypot(states[-1].x - 15.0, states[-1].y - 10.0)
    assert drift > 1e-4  # the rotation centre is not the body centre


def test_encoders_are_blind_to_slip():
    rng = np.random.default_rng(3)
    states = drive(RobotState(), 0.5, 0.0, 5.0, rng, soil=5.0)
    enc = np.mean([encoder_twist(s, rng, CFG)[0] for s in states[-50:]])
    true = np.mean([s.v for s in states[-50:]])
    assert enc > true * 1.04


def test_pitch_and_roll_follow_the_slope():
    ter = build_terrain(BOUNDS, TerrainConfig(slope_pct=5.0, slope_dir_deg=0, bump_rms=0), 0)
    facing_up = settle(RobotState(x=10.0, y=10.0, yaw=0.0), ter)
    assert facing_up.pitch == pytest.approx(-math.atan(0.05), abs=1e-9)  # nose up
    assert facing_up.roll == pytest.approx(0.0, abs=1e-9)
    assert facing_up.z == pytest.approx(float(ter.height(10.0, 10.0)), abs=1e-9)
    across = settle(RobotState(x=10.0, y=10.0, yaw=math.pi / 2), ter)
    assert across.roll == pytest.approx(-math.atan(0.05), abs=1e-9)  # right side up
    assert across.pitch == pytest.approx(0.0, abs=1e-9)


def test_lever_arm_through_full_pose():
    s = RobotState(x=1.0, y=2.0, z=0.1, roll=math.radians(1.0), yaw=0.0)
    p = body_to_field(s, np.array([[0.475, 0.0, 1.10], [-0.475, 0.0, 1.10]]))
    np.testing.assert_allclose(p[:, 1], 2.0 - 1.10 * math.sin(math.radians(1.0)), atol=1e-12)
    np.testing.assert_allclose(p[:, 0], [1.475, 0.525], atol=1e-12)


def test_bad_dt_is_rejected():
    with pytest.raises(ValueError, match="dt"):
        step(RobotState(), 0.0, 0.0, 0.0, FLAT, np.random.default_rng(0))
