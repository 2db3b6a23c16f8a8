"""The IMU's bias from turns in place: on the simulated ground with the simulated
UM7, and the spots that must teach nothing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.robot import ImuMount
from services.nav.tilt import Tilt, TiltConfig
from services.nav.turn_level import TurnLevel, TurnLevelConfig, fit_bias, heading_span
from services.sim.imu import ImuConfig, ImuModel
from services.sim.robot import RobotState, settle, step
from services.sim.terrain import TerrainConfig, build_terrain

TERRAIN = build_terrain(np.array([0.0, 0.0, 30.0, 20.0]), TerrainConfig(), seed=5)


def _turn_in_place(tilt: Tilt, imu: ImuModel, x: float, y: float, turn: float) -> float:
    """Stand 3 s, turn by ``turn`` rad at the Husky's 0.6 rad/s, stand 3 s, drive
    off; feeding ``tilt`` the UM7 and the true pose. Returns the sim time."""
    rng = np.random.default_rng(0)
    s = settle(RobotState(x=x, y=y, yaw=0.3), TERRAIN)
    t, dt = 0.0, 0.02
    phases = [(0.0, 3.0), (math.copysign(0.6, turn), abs(turn) / 0.6), (0.0, 3.0)]
    for w, length in [*phases, (0.0, 0.0)]:
        end = t + length
        while t < end or (length == 0.0 and t < end + 2.0):
            v = 0.3 if length == 0.0 else 0.0  # drive off at the end: the spot closes
            s = step(s, v, w, dt, TERRAIN, rng)
            t += dt
            tilt.motion(t, s.v_wheel, s.w_wheel)
            if round(t / dt) % 5 == 0:  # the UM7 at 10 Hz
                m = imu.read(t, s)
                tilt.imu(t, m.roll, m.pitch, (s.x, s.y, s.yaw))
    return t


@pytest.mark.parametrize("turn_deg", [90.0, 180.0])
def test_a_turn_in_place_on_the_simulated_ground_finds_the_um7s_bias(turn_deg: float) -> None:
    errors = []
    for seed, (x, y) in enumerate([(6.0, 4.0), (15.0, 10.0), (24.0, 16.0)]):
        imu = ImuModel(ImuConfig(tilt_bias_sd_deg=1.0), seed=seed)
        tilt = Tilt(TiltConfig(), ImuMount())
        assert tilt.bias == (0.0, 0.0)  # nothing known before the turn
        _turn_in_place(tilt, imu, x, y, math.radians(turn_deg))
        assert tilt.turns.spots == 1, "the turn gave no estimate"
        errors.append(np.degrees(np.subtract(tilt.bias, imu.tilt_bias)))
    # against biases of 1 deg SD: the terrain's bumps across the wheels' circle and
    # the UM7's noise leave a few hundredths of a degree (a few mm at the antennas)
    assert np.abs(errors).max() < 0.1, errors


def test_the_compensator_is_preferred_to_the_turns_once_a_scan_has_read_it() -> None:
    imu = ImuModel(ImuConfig(tilt_bias_sd_deg=1.0), seed=1)
    tilt = Tilt(TiltConfig(), ImuMount())
    t = _turn_in_place(tilt, imu, 10.0, 5.0, math.pi)
    turns = tilt.bias
    # a compensator reading says the robot stands level: bias = the IMU's tilt now
    raw = tilt.raw
    assert raw is not None and tilt.compensator(t, 0.0, 0.0)
    assert tilt.bias == pytest.approx(raw) and tilt.bias != pytest.approx(turns)


def test_standing_in_one_heading_or_driving_teaches_nothing() -> None:
    level = TurnLevel(TurnLevelConfig())
    for _ in range(200):  # 20 s standing, heading 0.3 rad, never turning
        level.sample(1.0, 2.0, 0.3, 0.0, 0.01, -0.02)
    for k in range(50):  # then driving off
        level.sample(1.0 + 0.03 * k, 2.0, 0.3, 0.3, 0.01, -0.02)
    assert level.spots == 0 and level.bias is None
    # a turn whose tilts do not fit a plane (a wheel on a stone half way round)
    for k in range(100):
        psi = 0.3 + math.pi * k / 99
        level.sample(5.0, 5.0, psi, 0.0, 0.01 + (0.05 if k > 50 else 0.0), -0.02)
    assert not level.close() and level.refused == 1 and level.bias is None


def test_the_fit_recovers_slope_and_bias_and_the_span_wraps_round() -> None:
    psi = np.linspace(-0.5, 1.2, 40)
    gx, gy, br, bp = 0.02, -0.01, 0.015, -0.008
    roll = -gx * np.sin(psi) + gy * np.cos(psi) + br
    pitch = -(gx * np.cos(psi) + gy * np.sin(psi)) + bp
    sol, rms = fit_bias(psi, roll, pitch)
    assert sol == pytest.approx([gx, gy, br, bp], abs=1e-9) and rms < 1e-9
    assert heading_span(np.array([3.0, -3.0])) == pytest.approx(2 * math.pi - 6.0)
