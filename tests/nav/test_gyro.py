"""The gyro's yaw rate: its bias learnt standing, and what it does to a skid-steer turn."""

from __future__ import annotations

import math

import numpy as np

from services.nav.ekf import EkfConfig, Localizer
from services.nav.gyro import Gyro, GyroConfig


def test_before_the_robot_stands_the_gyro_wins_a_turn_and_the_wheels_a_straight() -> None:
    gyro = Gyro(GyroConfig(sd=0.01, unknown_bias_sd=0.005))
    gyro.sample(0.1, 0.504, still=False)  # a turn; the bias (0.004) unknown
    w, _ = gyro.odometry_rate(0.12, 0.6, 1e-4 + (0.1 * 0.6) ** 2, 0.1)
    assert abs(w - 0.504) < 0.01  # not the scrubbing wheels' 0.6
    gyro.sample(0.2, 0.004, still=False)  # straight: the bias is all the gyro says
    w, _ = gyro.odometry_rate(0.22, 0.0, 1e-6, 0.1)
    assert abs(w) < 0.0005


def test_the_bias_is_learnt_standing_and_taken_off_the_rate() -> None:
    rng = np.random.default_rng(3)
    gyro = Gyro(GyroConfig(sd=0.01))
    unknown = gyro.bias_var
    t = 0.0
    for _ in range(300):
        t += 0.1
        gyro.sample(t, 0.004 + rng.normal(0, 0.01), still=True)
    assert gyro.bias_var < unknown / 50
    assert abs(gyro.bias - 0.004) < 0.002
    t += 0.1
    gyro.sample(t, 0.504, still=False)
    # in a turn the scrubbing wheels (0.06 rad/s) weigh little against the gyro
    w, var = gyro.odometry_rate(t + 0.02, 0.6, 0.06**2, 0.1)
    assert abs(w - 0.5) < 0.02 and var < 0.01**2
    # at a creep the wheels are the better measurement
    gyro.sample(t + 0.1, 0.004 + 0.02, still=False)  # 0.015 rad/s of noise over 0.005
    w, _ = gyro.odometry_rate(t + 0.12, 0.005, 1e-6, 0.1)
    assert abs(w - 0.005) < 0.001
    # a stale rate is not used
    assert gyro.odometry_rate(t + 1.1, 0.6, 0.06**2, 0.02) == (0.6, 0.06**2)


def test_a_sample_used_for_several_odometry_updates_weighs_as_one() -> None:
    gyro = Gyro(GyroConfig(sd=0.01, unknown_bias_sd=1e-9))
    gyro.sample(0.0, 0.0, still=True)
    gyro.sample(0.1, 0.3, still=False)
    gyro.sample(0.2, 0.3, still=False)
    _, var_once = gyro.odometry_rate(0.2, 0.3, 1.0, 0.1)
    _, var_fifth = gyro.odometry_rate(0.2, 0.3, 1.0, 0.02)
    assert math.isclose(var_fifth / var_once, 5.0, rel_tol=0.01)


def test_absurd_readings_are_refused_and_a_disabled_gyro_says_nothing() -> None:
    gyro = Gyro(GyroConfig())
    gyro.sample(0.0, 0.0, still=True)
    gyro.sample(0.1, math.nan, still=False)
    gyro.sample(0.2, 50.0, still=False)
    assert gyro.refused == 2
    assert gyro.odometry_rate(0.25, 0.2, 1.0, 0.02) == (0.2, 1.0)
    off = Gyro(GyroConfig(enabled=False))
    off.sample(0.0, 0.0, still=True)
    off.sample(0.1, 0.3, still=False)
    assert off.odometry_rate(0.12, 0.2, 1.0, 0.02) == (0.2, 1.0)


def _turn(with_gyro: bool, stood: bool = True) -> float:
    """A 90 deg turn in place on loose ground: the body yaws at 85 % of the rate the
    wheels imply (odometry stated as the base states it: 10 % of the rate), and no
    compass heading arrives during the turn; the gyro's bias (0.004 rad/s) learnt
    standing, or unknown. The filter's heading error at its end (deg)."""
    rng = np.random.default_rng(7)
    gyro = Gyro(GyroConfig())
    bias = 0.004
    for k in range(300 if stood else 0):
        gyro.sample(-30.0 + 0.1 * k, bias + rng.normal(0, 0.01), still=True)
    loc = Localizer(EkfConfig())
    loc.update_heading(0.0, 0.0, math.radians(0.5))
    loc.update_antenna(0.0, [0.0, 0.0], np.eye(2) * 1e-4, (0.0, 0.0))
    yaw, dt, t = 0.0, 0.02, 0.0
    w_wheels = 0.6
    while yaw < math.pi / 2:
        t += dt
        w_true = 0.85 * w_wheels
        yaw += w_true * dt
        if with_gyro and round(t / dt) % 5 == 1:  # 10 Hz
            gyro.sample(t, w_true + bias + rng.normal(0, 0.01), still=False)
        w, var_w = w_wheels + rng.normal(0, 0.01), 1e-4 + (0.1 * w_wheels) ** 2
        w, var_w = gyro.odometry_rate(t, w, var_w, dt)
        loc.update_odometry(t, 0.0, w, 1e-4, var_w)
    return math.degrees(abs(loc.x[2] - yaw))


def test_the_gyro_keeps_the_heading_through_a_slipping_turn() -> None:
    without, with_gyro = _turn(with_gyro=False), _turn(with_gyro=True)
    assert without > 10.0
    assert with_gyro < 0.2 * without
    # a robot that drove off before standing (or a navigation restarted on the move)
    assert _turn(with_gyro=True, stood=False) < 0.2 * without
