"""Navigation in the simulated world with real processes: the lidar obstacle stop and
the stop when localization is lost."""

from __future__ import annotations

import math
import signal
import time
from pathlib import Path

from common import keys
from common.cli import wait_alive
from common.messages.nav import FollowRoute, Leg, NavState
from common.transport import Bus, RpcError
from tests.conftest import Procs

SIM = ("--clock", "sim", "--field", "engr")


def start_world(
    procs: Procs, ep: str, bus: Bus, tmp: Path, sim_sets: list[str], nav_sets: list[str]
) -> dict[str, int]:
    pids = {}
    for name, sets in (
        ("sim", ["real_time_factor=4.0", *sim_sets]),
        ("base", []),
        ("gnss", []),
        ("nav", nav_sets),
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
            assert bus.call(keys.NAV_CMD, FollowRoute(route_id="r", legs=legs), timeout=2).accepted
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


def test_losing_localization_stops_the_robot(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    pids = start_world(
        procs, router_endpoint, client_bus, tmp_path, [], ["ekf.localized_sigma_m=0.03"]
    )
    truth = client_bus.latest(keys.SIM_TRUTH)
    progress = client_bus.latest(keys.NAV_PROGRESS)
    send_route(client_bus, WEST)
    assert progress.wait_for(
        lambda p: p.state == NavState.DRIVING and p.distance_to_go < 8.5, timeout=60
    )
    import os

    os.kill(pids["gnss"], signal.SIGKILL)  # no more fixes: the covariance must grow
    lost = progress.wait_for(lambda p: p.state == NavState.NOT_LOCALIZED, timeout=60)
    assert lost is not None
    stopped = truth.wait_for(lambda t: abs(t.v) < 0.01 and abs(t.w) < 0.01, timeout=20)
    assert stopped is not None and stopped.x > 19.6, stopped
    pose = client_bus.latest(keys.NAV_POSE).wait_for(lambda p: True, timeout=5)
    assert pose is not None and not pose.localized
    assert math.sqrt(max(pose.covariance[0], pose.covariance[4])) > 0.03
