"""Navigation in the simulated world with real processes: the lidar obstacle stop and
the stop when localization is lost."""

from __future__ import annotations

import math
import os
import signal
import time
from pathlib import Path
from typing import TypeVar

from common import keys
from common.client import wait_alive
from common.messages.nav import LEASE_ENDED, FollowRoute, Leg, NavState
from common.messages.sim import TruthPose
from common.transport import Bus, RpcError
from tests.conftest import Procs, Record, record

SIM = ("--clock", "sim", "--field", "engr")
M = TypeVar("M")


def start_world(
    procs: Procs, ep: str, bus: Bus, tmp: Path, sim_sets: list[str], nav_sets: list[str]
) -> dict[str, int]:
    pids = {}
    for name, sets in (
        ("sim", ["real_time_factor=4.0", *sim_sets]),
        ("base", ["backend=sim"]),
        ("gnss", ["backend=sim"]),
        # the stops are timed from twice the default cruise speed: the harder case
        ("nav", ["follower.max_speed=0.3", *nav_sets]),
    ):
        args = [a for s in sets for a in ("--set", s)]
        pids[name] = procs.service(f"services.{name}", ep, *SIM, *args, log=tmp / f"{name}.log").pid
    assert wait_alive(bus.session, {"sim", "base", "gnss", "nav"}, timeout=30)
    pose = bus.latest(keys.NAV_POSE)
    assert pose.wait_for(lambda p: p.localized, timeout=60), "never localized"
    return pids


def send_route(bus: Bus, legs: list[Leg]) -> None:
    deadline = time.monotonic() + 10
    while True:
        try:
            assert bus.call(
                keys.NAV_CMD, FollowRoute(route_id="r", legs=legs, lease_s=3600.0), timeout=2
            ).accepted
            return
        except RpcError:
            assert time.monotonic() < deadline


WEST = [Leg(x0=28.5, y0=1.0, x1=19.5, y1=1.0)]


def test_obstacle_stop_then_blocked(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    box = "world.obstacles=[{type='box', x=24.0, y=1.0, size_x=0.3, size_y=0.3, height=0.5}]"
    start_world(
        procs, router_endpoint, client_bus, tmp_path, [box], ["follower.obstacle_timeout_s=10.0"]
    )
    truth = client_bus.latest(keys.SIM_TRUTH)
    progress = client_bus.latest(keys.NAV_PROGRESS)
    send_route(client_bus, WEST)
    waiting = progress.wait_for(lambda p: p.state == NavState.WAITING_OBSTACLE, timeout=60)
    assert waiting is not None
    t = truth.get()
    assert t is not None and 24.15 + 0.495 < t.x < 25.5, t  # stopped short of the box
    blocked = progress.wait_for(lambda p: p.state == NavState.BLOCKED, timeout=30)
    assert blocked is not None
    t2 = truth.get()
    assert t2 is not None and t2.x > 24.15 + 0.495 and abs(t2.v) < 0.02


# standing: below 2 cm/s the drivetrain's 0.15 s lag leaves under 3 mm to roll
STILL = 0.02


def first_still_after(truth: list[TruthPose], t_ns: int) -> TruthPose | None:
    return next((t for t in truth if t.stamp_ns >= t_ns and abs(t.v) < STILL), None)


def drive_west(bus: Bus) -> Record[TruthPose]:
    """Send WEST and return the truth recorded from before it, once the robot drives."""
    truth = record(bus, keys.SIM_TRUTH)
    assert truth.wait_for(lambda t: True, timeout=10), "no truth from the simulator"
    send_route(bus, WEST)
    assert bus.latest(keys.NAV_PROGRESS).wait_for(
        lambda p: p.state == NavState.DRIVING and p.distance_to_go < 8.0, timeout=60
    )
    return truth


def test_losing_rtk_stops_the_robot_in_about_a_second(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    # real time, truth at 50 Hz: a stop bound in seconds is a real-time figure (at 4x
    # every 10 ms of delivery and scheduling would count 40 ms)
    rt = ["real_time_factor=1.0", "truth_hz=50.0"]
    pids = start_world(procs, router_endpoint, client_bus, tmp_path, rt, [])
    fixes = record(client_bus, keys.GNSS_FIX.at(antenna=1))
    truth = drive_west(client_bus)
    progress = client_bus.latest(keys.NAV_PROGRESS)
    os.kill(pids["gnss"], signal.SIGKILL)  # no more fixes
    killed = truth[-1].stamp_ns
    lost = progress.wait_for(lambda p: p.state == NavState.NOT_LOCALIZED, timeout=30)
    assert lost is not None
    last_fix = fixes[-1].stamp_ns
    moving = [t for t in truth if t.stamp_ns <= last_fix][-1]
    assert abs(moving.v) > 0.2, "the robot was not driving when the fixes stopped"
    assert truth.wait_for(lambda t: t.stamp_ns > killed and abs(t.v) < STILL, timeout=20)
    still = first_still_after(truth, last_fix)
    assert still is not None
    # The 1 s target is a benchmark figure (the fault campaign's rtk-outage row measures it,
    # 0.90 s): here, on a loaded 2-core CI runner, scheduling adds tens of milliseconds of
    # real time to a chain of four processes, so the test asserts the behaviour (a stop in
    # about a second, not the seconds of waiting for sigma to grow) with room for that.
    assert (still.stamp_ns - last_fix) / 1e9 <= 1.5, (still.stamp_ns - last_fix) / 1e9
    assert math.hypot(still.x - moving.x, still.y - moving.y) <= 0.5


def test_a_route_not_renewed_stops_the_robot(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    start_world(procs, router_endpoint, client_bus, tmp_path, [], [])
    truth = record(client_bus, keys.SIM_TRUTH)
    assert truth.wait_for(lambda t: True, timeout=10), "no truth from the simulator"
    progress = client_bus.latest(keys.NAV_PROGRESS)
    client_bus.call(keys.NAV_CMD, FollowRoute(route_id="leased", legs=WEST, lease_s=12.0))
    failed = progress.wait_for(
        lambda p: p.route_id == "leased" and p.state == NavState.FAILED, timeout=60
    )
    assert failed is not None and failed.detail.startswith(LEASE_ENDED), failed
    # the robot turns to the leg (about 5 s) and drives off before the lease ends
    assert max(abs(t.v) for t in truth) > 0.2, "the robot never drove"
    assert truth.wait_for(lambda t: t.stamp_ns > failed.stamp_ns and abs(t.v) < STILL, timeout=20)
    still = first_still_after(truth, failed.stamp_ns)
    # braking from 0.5 m/s at 1 m/s^2 through a 0.15 s lag: about 0.6 s; at 4x real time
    # each 10 ms of scheduling on a loaded runner counts 40 ms, hence the room
    assert still is not None and (still.stamp_ns - failed.stamp_ns) / 1e9 <= 1.5


def test_navigation_killed_while_driving_the_base_stops_the_wheels(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    # real time, truth at 50 Hz, as for the RTK loss: at 4x every 10 ms of liveliness
    # delivery and scheduling on a loaded machine would count 40 ms of sim time
    rt = ["real_time_factor=1.0", "truth_hz=50.0"]
    pids = start_world(procs, router_endpoint, client_bus, tmp_path, rt, [])
    cmds = record(client_bus, keys.BASE_CMD_VEL)
    truth = drive_west(client_bus)
    # the truth as it is delivered, not as nav saw it: on a loaded machine the newest
    # truth received may still be from before the robot got going
    assert truth.wait_for(lambda t: abs(t.v) > 0.25, timeout=30), "the robot never drove"
    os.kill(pids["nav"], signal.SIGKILL)
    assert truth and cmds, (len(truth), len(cmds))
    killed = truth[-1].stamp_ns
    assert truth.wait_for(lambda t: t.stamp_ns > killed and abs(t.v) < STILL, timeout=20)
    moving = [t for t in truth if t.stamp_ns <= killed][-1]
    assert abs(moving.v) > 0.2
    still = first_still_after(truth, killed)
    assert still is not None
    # the base stops the wheels as nav's liveliness token goes, not 0.25 s later at its
    # watchdog; braking from 0.5 m/s at the sim's 1 m/s^2 through a 0.15 s lag to below
    # STILL takes about 0.65 s and 0.15 m
    stop_s = (still.stamp_ns - killed) / 1e9
    print(f"stood {stop_s:.2f} s, {math.hypot(still.x - moving.x, still.y - moving.y):.3f} m")
    assert stop_s <= 1.0, stop_s
    assert math.hypot(still.x - moving.x, still.y - moving.y) <= 0.2
    assert "nav is gone" in (tmp_path / "base.log").read_text()
