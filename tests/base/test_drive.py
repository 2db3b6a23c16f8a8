from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from services.base.drive import CommandGate, OdometryIntegrator

MS = 1_000_000


def test_watchdog_stops_the_wheels_after_silence() -> None:
    g = CommandGate(1.0, 2.0, 500 * MS)
    assert g.output(0) == (0.0, 0.0)  # never commanded
    g.command(0.5, 0.1, 0)
    assert g.output(499 * MS) == (0.5, 0.1)
    assert g.output(501 * MS) == (0.0, 0.0) and g.watchdog_tripped(501 * MS)
    g.command(0.2, 0.0, 600 * MS)
    assert g.output(700 * MS) == (0.2, 0.0)


def test_estop_overrides_and_release_does_not_resume() -> None:
    g = CommandGate(1.0, 2.0, 500 * MS)
    g.command(0.5, 0.0, 0)
    g.set_estop(True, "operator")
    g.command(0.5, 0.0, 10 * MS)
    assert g.output(20 * MS) == (0.0, 0.0)
    g.set_estop(False)
    assert g.output(30 * MS) == (0.0, 0.0)  # the old command is gone
    g.command(0.3, 0.0, 40 * MS)
    assert g.output(50 * MS) == (0.3, 0.0)


@given(st.floats(-10, 10), st.floats(-10, 10))
def test_commands_are_clamped_to_limits(v: float, w: float) -> None:
    g = CommandGate(1.0, 2.0, 500 * MS)
    g.command(v, w, 0)
    ov, ow = g.output(1)
    assert abs(ov) <= 1.0 and abs(ow) <= 2.0


def test_odometry_follows_a_circle() -> None:
    odo = OdometryIntegrator()
    r, v = 2.0, 0.5
    for k in range(0, 1001):
        odo.update(v, v / r, k * 10 * MS)  # 10 s at 100 Hz: 5 m of arc
    ang = 5.0 / r
    assert math.isclose(odo.x, r * math.sin(ang), abs_tol=1e-6)
    assert math.isclose(odo.y, r * (1 - math.cos(ang)), abs_tol=1e-6)
    assert math.isclose(odo.yaw, ang, abs_tol=1e-9)


def test_hold_stops_at_once_and_waits_for_a_fresh_command() -> None:
    g = CommandGate(1.0, 2.0, 250 * MS)
    g.command(0.5, 0.1, 0)
    assert g.output(10 * MS) == (0.5, 0.1)
    g.hold()
    assert g.output(11 * MS) == (0.0, 0.0) and g.watchdog_tripped(11 * MS)
    g.command(0.2, 0.0, 20 * MS)
    assert g.output(21 * MS) == (0.2, 0.0)
