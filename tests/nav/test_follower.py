"""The follower closing the loop around a simple unicycle (no slip): a square route
with in-place corners ends at the goal, within the heading tolerance."""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np
import pytest

from common.geo import wrap_angle
from common.messages.nav import Leg, NavState
from services.nav.fine import pose_sds
from services.nav.follower import Follower, FollowerConfig
from services.nav.follower_types import Tick


def run(
    f: Follower,
    x: float,
    y: float,
    yaw: float,
    seconds: float,
    obstacle_until: float = -1.0,
    localized: bool = True,
):
    dt = 0.05
    events, xtes = [], []
    for k in range(int(seconds / dt)):
        t = k * dt
        c = f.step(t, x, y, yaw, localized, t < obstacle_until)
        if c.event:
            events.append(c.event)
        if c.state == NavState.DRIVING:
            xtes.append(abs(c.cross_track))
        x += c.v * dt * math.cos(yaw)
        y += c.v * dt * math.sin(yaw)
        yaw = wrap_angle(yaw + c.w * dt)
    return x, y, yaw, events, xtes


def square() -> list[Leg]:
    pts = [(0, 0), (5, 0), (5, 3), (0, 3), (0, 0)]
    legs = []
    for i in range(4):
        (x0, y0), (x1, y1) = pts[i], pts[i + 1]
        nx, ny = pts[(i + 2) % 5] if i < 3 else (5, 0)
        legs.append(Leg(x0=x0, y0=y0, x1=x1, y1=y1, final_yaw=math.atan2(ny - y1, nx - x1)))
    return legs


def test_square_route_arrives_once_within_tolerances() -> None:
    f = Follower(FollowerConfig())
    f.start("sq", square())
    x, y, yaw, events, xtes = run(f, 0.0, 0.0, 0.0, 240.0)
    assert events == ["arrived"]
    assert math.hypot(x, y) < 0.03
    assert abs(wrap_angle(yaw - 0.0)) <= math.radians(2.0) + 1e-6
    assert max(xtes) < 0.05


def test_in_place_rotation_ends_within_tolerance() -> None:
    f = Follower(FollowerConfig())
    f.start("turn", [Leg(x0=0, y0=0, x1=0, y1=0, final_yaw=math.radians(90))])
    _, _, yaw, events, _ = run(f, 0.0, 0.0, 0.0, 60.0)
    assert events == ["arrived"]
    assert abs(wrap_angle(yaw - math.radians(90))) <= math.radians(2.0)


def test_obstacle_waits_then_resumes_or_blocks() -> None:
    f = Follower(FollowerConfig(obstacle_timeout_s=10.0))
    f.start("a", [Leg(x0=0, y0=0, x1=3, y1=0)])
    x, _, _, events, _ = run(f, 0.0, 0.0, 0.0, 60.0, obstacle_until=5.0)
    assert events == ["arrived"] and abs(x - 3.0) < 0.03
    f = Follower(FollowerConfig(obstacle_timeout_s=10.0))
    f.start("b", [Leg(x0=0, y0=0, x1=3, y1=0)])
    x, _, _, events, _ = run(f, 0.0, 0.0, 0.0, 30.0, obstacle_until=100.0)
    assert events == ["blocked"] and x == 0.0 and f.state == NavState.BLOCKED


def test_no_motion_while_not_localized() -> None:
    f = Follower(FollowerConfig())
    f.start("c", [Leg(x0=0, y0=0, x1=3, y1=0)])
    x, _, _, events, _ = run(f, 0.0, 0.0, 0.0, 10.0, localized=False)
    assert x == 0.0 and events == [] and f.state == NavState.NOT_LOCALIZED


def run_lagging(
    f: Follower,
    x: float,
    y: float,
    yaw: float,
    seconds: float = 300.0,
    heading_sd: float = 0.0,
    at: list[float] | None = None,
) -> tuple[float, float, float, list[str]]:
    """Close the loop around a unicycle whose wheels follow commands with a 0.15 s
    lag (which overshoots a plain stop by centimetres), until an event (its time
    appended to ``at``)."""
    v = w = 0.0
    dt, tau = 0.05, 0.15
    for k in range(int(seconds / dt)):
        c = f.step(k * dt, x, y, yaw, True, False, heading_sd=heading_sd)
        if c.event:
            if at is not None:
                at.append(k * dt)
            return x, y, yaw, [c.event]
        v += (c.v - v) * (1 - math.exp(-dt / tau))
        w += (c.w - w) * (1 - math.exp(-dt / tau))
        x += v * dt * math.cos(yaw)
        y += v * dt * math.sin(yaw)
        yaw = wrap_angle(yaw + w * dt)
    return x, y, yaw, []


def test_fine_positioning_at_the_goal_with_a_lagging_drivetrain() -> None:
    cfg = FollowerConfig()
    f = Follower(cfg)
    goal_yaw = math.radians(90)
    f.start("fine", [Leg(x0=0, y0=0, x1=4, y1=0, final_yaw=goal_yaw)])
    x, _, yaw, events = run_lagging(f, 0.0, 0.0, 0.0)
    assert events == ["arrived"]
    assert abs(x - 4.0) <= cfg.fine_tolerance_m
    assert abs(math.degrees(wrap_angle(yaw - goal_yaw))) <= cfg.fine_heading_tolerance_deg


def test_the_place_along_the_leg_is_fine_tuned_before_turning_to_another_heading() -> None:
    """Stopped 1 cm short of a goal whose planned heading is 90 deg off the leg's:
    once turned, creeping along the new heading could not reach it, so the place
    comes first."""
    cfg = FollowerConfig()
    f = Follower(cfg)
    goal_yaw = math.radians(-90)
    f.start("short", [Leg(x0=0, y0=0, x1=2, y1=0, final_yaw=goal_yaw)])
    x, y, yaw, events = run_lagging(f, 1.985, 0.0, 0.0)
    assert events == ["arrived"]
    assert math.hypot(x - 2.0, y) <= cfg.fine_tolerance_m
    assert abs(math.degrees(wrap_angle(yaw - goal_yaw))) <= cfg.fine_heading_tolerance_deg


def test_a_sideways_offset_at_the_goal_is_driven_out_by_backing_up() -> None:
    """Stopped 5 cm beside the goal (a skid-steer robot cannot creep sideways), the
    robot backs up along the leg and comes in again, ending within the tolerances."""
    cfg = FollowerConfig()
    f = Follower(cfg)
    f.start("side", [Leg(x0=0, y0=0, x1=2, y1=0)])
    x, y, yaw, events = run_lagging(f, 1.99, 0.05, 0.0)
    assert events == ["arrived"]
    assert abs(y) <= cfg.reapproach_tolerance_m and abs(x - 2.0) <= cfg.fine_tolerance_m
    # a scan location plans no heading: the one the robot came in with is kept
    assert abs(math.degrees(yaw)) <= cfg.heading_tolerance_deg
    assert "trim" not in f.end_detail, f.end_detail
    assert f.fine.reapproaches >= 1
    # the arrival says what the fine phase did
    assert re.search(r"re-approach [+-]50 mm aside", f.end_detail), f.end_detail
    assert "the last settle" in f.end_detail


def test_a_planned_heading_is_trimmed_no_finer_than_the_estimate_knows_it() -> None:
    """Arrived 1 deg off a planned heading: trimmed when the filter's heading SD is
    below that, left as it is when the SD is 2 deg (the trim would chase noise)."""
    cfg = FollowerConfig(align_tolerance_deg=2.0)  # no turn before the (zero-length) drive
    for sd_deg, trimmed in ((0.0, True), (2.0, False)):
        f = Follower(cfg)
        f.start("trim", [Leg(x0=0, y0=0, x1=2, y1=0, final_yaw=0.0)])
        _, _, yaw, events = run_lagging(
            f, 2.0, 0.0, math.radians(1.0), heading_sd=math.radians(sd_deg)
        )
        assert events == ["arrived"]
        assert ("trim" in f.end_detail) is trimmed, f.end_detail
        off = abs(math.degrees(yaw))
        assert off <= cfg.fine_heading_tolerance_deg if trimmed else off == pytest.approx(1.0)


def test_the_arrival_settle_waits_for_the_estimate_to_settle() -> None:
    """Standing at the goal, the fine phase moves only once the estimate's position
    SD is below ``fine_settle_sd_m``, and at the latest after ``fine_settle_max_s``."""
    cfg = FollowerConfig(
        fine_settle_s=20.0, fine_settle_sd_m=0.004, fine_settle_max_s=90.0, fine_tolerance_m=0.005
    )

    def first_creep(sd_at: Callable[[float], float]) -> float:
        f = Follower(cfg)
        f.start("settle", [Leg(x0=0, y0=0, x1=2, y1=0)])
        dt = 0.05
        for k in range(int(120 / dt)):
            t = k * dt
            # 1 cm short of the goal, on the line: a creep is due once settled
            if f.step(t, 1.99, 0.0, 0.0, True, False, position_sd=sd_at(t)).v:
                return t
        raise AssertionError("never crept")

    assert first_creep(lambda t: 0.002) == pytest.approx(20.0, abs=0.1)
    assert first_creep(lambda t: 0.010 if t < 47.0 else 0.003) == pytest.approx(47.0, abs=0.1)
    assert first_creep(lambda t: 0.010) == pytest.approx(90.0, abs=0.1)


def test_no_fine_positioning_when_disabled() -> None:
    f = Follower(FollowerConfig(fine=False))
    f.start("coarse", [Leg(x0=0, y0=0, x1=1, y1=0)])
    _, _, _, events, _ = run(f, 0.0, 0.0, 0.0, 20.0)
    assert events == ["arrived"]
    assert f.phase.value == "final"


def test_arrival_checks_the_heading_with_its_own_tolerance() -> None:
    def at(x: float) -> Tick:
        return Tick(0.0, 0.0, x, 0.0, 0.0, False, leg, 0.0, 0.0, 0.0, 0.0)

    # a route ended on the spot but 5 deg off its planned heading (pure pursuit arrives
    # at an angle while it closes a sideways offset): not arrived...
    leg = Leg(x0=0, y0=0, x1=1, y1=0, final_yaw=0.0)
    strict = Follower(FollowerConfig(fine=False))
    strict.start("r", [leg])
    c = strict._arrive(at(1.0), math.radians(5.0))
    assert c.state == NavState.FAILED and "+5.00 deg" in c.detail
    # ...unless the arrival's own heading tolerance allows it (the paper profile scans
    # wherever it stopped), whatever the in-place turn's tolerance
    loose = Follower(FollowerConfig(fine=False, arrival_heading_tolerance_deg=180.0))
    loose.start("r", [leg])
    assert loose._arrive(at(1.0), math.radians(5.0)).state == NavState.ARRIVED
    assert loose._arrive(at(1.1), 0.0).state == NavState.FAILED  # 10 cm off
    # the distance is the route's own: a route asking 25 cm arrives 10 cm off
    loose.start("r", [leg], arrival_tolerance_m=0.25)
    assert loose._arrive(at(1.1), 0.0).state == NavState.ARRIVED


def test_the_fine_phase_reads_the_worse_axis_and_an_unknown_covariance_as_infinite() -> None:
    cov = np.diag([1e-6, 16e-6, 1e-4])
    assert pose_sds(cov) == pytest.approx((0.004, 0.01))
    cov[2, 2] = math.nan
    assert pose_sds(cov) == (math.inf, math.inf)


def start_beside_the_line(cfg: FollowerConfig) -> tuple[float, float, list[float], NavState]:
    """A corner's turn in place left the robot 8 cm beside the next leg, facing across
    it; driven behind a lagging drivetrain. Its offset and heading as it starts
    driving the leg, its offsets after a metre of it, and how the route ended."""
    f = Follower(cfg)
    f.start("side", [Leg(x0=0, y0=0, x1=5, y1=0)])
    x, y, yaw, v, w = 0.0, 0.08, math.pi / 2, 0.0, 0.0
    dt, tau = 0.05, 0.15
    first: tuple[float, float] | None = None
    after_a_metre = []
    for k in range(int(60 / dt)):
        c = f.step(k * dt, x, y, yaw, True, False)
        if c.state == NavState.DRIVING and first is None:
            first = (y, yaw)
        if x > 1.0 and c.state == NavState.DRIVING:
            after_a_metre.append(abs(y))
        if c.event:
            break
        v += (c.v - v) * (1 - math.exp(-dt / tau))
        w += (c.w - w) * (1 - math.exp(-dt / tau))
        x += v * dt * math.cos(yaw)
        y += v * dt * math.sin(yaw)
        yaw = wrap_angle(yaw + w * dt)
    assert first is not None
    return first[0], first[1], after_a_metre, f.state


def test_a_leg_started_beside_its_line_is_back_on_it_within_a_metre_at_speed() -> None:
    """Turning onto the leg, the robot drives along its heading toward the line, so
    it starts the leg on it; turning strictly in place, it turns toward the line, not
    along it, and at 0.5 m/s is back within a centimetre after a metre of the leg,
    without overshooting by more."""
    y0, _, after, state = start_beside_the_line(FollowerConfig())
    assert abs(y0) < 0.01 and max(after) < 0.01 and state == NavState.ARRIVED
    y0, yaw0, after, state = start_beside_the_line(FollowerConfig(turn_hold_gain=0.0))
    assert y0 > 0.07 and math.degrees(yaw0) < -5.0
    assert max(after) < 0.01 and state == NavState.ARRIVED


def rotating_seconds(cfg: FollowerConfig) -> float:
    """Seconds spent turning in place over two lane changes (four right angles),
    around the lagging unicycle of :func:`run_lagging`."""
    f = Follower(cfg)
    legs = [(0, 0, 12, 0), (12, 0, 12, 0.8), (12, 0.8, 0, 0.8), (0, 0.8, 0, 1.6), (0, 1.6, 6, 1.6)]
    f.start("lanes", [Leg(x0=a, y0=b, x1=c, y1=d) for a, b, c, d in legs])
    x = y = yaw = v = w = 0.0
    dt, tau, turning = 0.05, 0.15, 0.0
    for k in range(int(300 / dt)):
        c = f.step(k * dt, x, y, yaw, True, False)
        if c.event:
            assert c.event == "arrived" and math.hypot(x - 6, y - 1.6) < 0.05
            return turning
        turning += dt if c.state == NavState.ROTATING else 0.0
        v += (c.v - v) * (1 - math.exp(-dt / tau))
        w += (c.w - w) * (1 - math.exp(-dt / tau))
        x, y = x + v * dt * math.cos(yaw), y + v * dt * math.sin(yaw)
        yaw = wrap_angle(yaw + w * dt)
    raise AssertionError("the route did not end")


def test_a_turn_in_place_takes_about_its_physical_time() -> None:
    cfg = FollowerConfig()
    rate, accel = cfg.max_turn_rate, cfg.max_turn_accel
    assert math.pi / 2 > rate * rate / accel  # it reaches its rate: a trapezoid
    physical = 4 * (math.pi / 2 / rate + rate / accel)
    took = rotating_seconds(cfg)
    assert took <= 1.25 * physical, (took, physical)
    # a proportional law alone at the same limits spends seconds in its tail
    tail = rotating_seconds(FollowerConfig(rotate_gain=1.5, turn_braking=1.0))
    assert tail > 1.4 * took, (tail, took)
