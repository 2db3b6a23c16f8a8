"""GNSS compass (paper eq. 2): quadrants, wrap, uncertainty, baseline check."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from common.geo import wrap_angle
from services.gnss.compass import (
    BaselineMismatch,
    Compass,
    CompassError,
    compass_heading,
)

L = 0.95
COV = np.diag([0.007**2, 0.007**2, 0.014**2])


def antennas(yaw: float, x: float = 10.0, y: float = -5.0) -> tuple[np.ndarray, np.ndarray]:
    """Rear and front antenna positions for a robot at (x, y) with heading ``yaw``."""
    u = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    c = np.array([x, y, 1.1])
    return c - u * L / 2, c + u * L / 2


@pytest.mark.parametrize(("yaw_deg"), [0.0, 30.0, 90.0, 135.0, 179.9, -179.9, -135.0, -90.0, -45.0])
def test_heading_in_every_quadrant(yaw_deg: float) -> None:
    p1, p2 = antennas(math.radians(yaw_deg))
    h = compass_heading(p1, p2, COV, COV)
    assert math.degrees(h.yaw_rad) == pytest.approx(yaw_deg, abs=1e-9)
    assert h.baseline_m == pytest.approx(L)


def test_east_is_zero_and_north_is_plus_90() -> None:
    # REP-103 in an ENU frame: +x east is yaw 0, +y north is +pi/2.
    assert compass_heading([0, 0], [L, 0], COV, COV).yaw_rad == pytest.approx(0.0)
    assert compass_heading([0, 0], [0, L], COV, COV).yaw_rad == pytest.approx(math.pi / 2)


def test_heading_wraps_to_minus_pi() -> None:
    h = compass_heading([0, 0, 0], [-L, 0, 0], COV, COV)
    assert h.yaw_rad == pytest.approx(-math.pi)


@given(st.floats(-100.0, 100.0, allow_nan=False))
def test_wrap_angle_range(a: float) -> None:
    w = wrap_angle(a)
    assert -math.pi <= w < math.pi
    assert math.sin(w) == pytest.approx(math.sin(a), abs=1e-9)
    assert math.cos(w) == pytest.approx(math.cos(a), abs=1e-9)


def test_yaw_sigma_formula() -> None:
    h = compass_heading(*antennas(0.3), COV, COV)
    assert h.yaw_std_rad == pytest.approx(math.sqrt(2) * 0.007 / L)
    assert math.degrees(h.yaw_std_rad) == pytest.approx(0.6, abs=0.01)


def test_only_perpendicular_error_matters() -> None:
    # Error purely along the baseline (x here) gives no yaw uncertainty.
    along = np.diag([0.01**2, 0.0])
    assert compass_heading([0, 0], [L, 0], along, along).yaw_std_rad == pytest.approx(0.0)


def test_heading_sd_with_7mm_noise_is_about_0_6_deg() -> None:
    rng = np.random.default_rng(42)
    n = 20_000
    truth = rng.uniform(-math.pi, math.pi, n)
    errs = []
    noise1, noise2 = rng.normal(0, 0.007, (n, 3)), rng.normal(0, 0.007, (n, 3))
    for yaw, e1, e2 in zip(truth, noise1, noise2, strict=True):
        p1, p2 = antennas(float(yaw))
        h = compass_heading(p1 + e1, p2 + e2, COV, COV)
        errs.append(wrap_angle(h.yaw_rad - yaw))
    sd_deg = math.degrees(float(np.std(errs)))
    assert sd_deg == pytest.approx(0.597, rel=0.03)
    assert abs(math.degrees(float(np.mean(errs)))) < 0.02


def test_wrong_baseline_is_rejected() -> None:
    p1, p2 = antennas(1.0)
    with pytest.raises(BaselineMismatch, match=r"baseline 1\.050 m, expected 0\.950 m"):
        compass_heading(p1, p2 + np.array([math.cos(1.0), math.sin(1.0), 0]) * 0.1, COV, COV)


def test_pitch_from_heights() -> None:
    # Front antenna 5 cm higher: nose up, which is negative pitch in REP-103.
    h = compass_heading([0, 0, 1.1], [math.sqrt(L**2 - 0.05**2), 0, 1.15], COV, COV)
    assert h.pitch_rad == pytest.approx(-math.asin(0.05 / L))
    assert h.yaw_rad == pytest.approx(0.0)


def test_mounting_offset() -> None:
    # Antennas across the robot (2 on the left): the baseline points at robot +y.
    cfg = Compass(antenna1_xyz_m=(0.0, -0.475, 1.1), antenna2_xyz_m=(0.0, 0.475, 1.1))
    h = compass_heading([0, 0], [0, L], COV, COV, cfg)
    assert h.yaw_rad == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("p1", "p2", "cov"),
    [
        ([0, 0], [L, 0, 0], COV),
        ([0, math.nan], [L, 0], COV),
        ([0, 0], [L, 0], np.eye(4)),
        ([0, 0, 0], [0.1, 0, 0.94], COV),
    ],
)
def test_malformed_input(p1: list, p2: list, cov: np.ndarray) -> None:
    with pytest.raises(CompassError):
        compass_heading(p1, p2, cov, COV)
