"""What ``phenorover nav-test`` records of a run (truth, estimates, progress), and the
route it has navigation follow, leased and renewed."""

from __future__ import annotations

import contextlib
import threading
import time

from common import keys
from common.messages.nav import FollowRoute, Leg, NavProgress, NavState, PoseEstimate, RenewRoute
from common.messages.sim import TruthPose
from common.transport import Bus, RpcError

LEASE_S = 3600.0  # the longest a route may be leased for (FollowRoute.lease_s)


class Recorder:
    """Truth, estimates and progress, as they arrive."""

    def __init__(self, bus: Bus) -> None:
        self.lock = threading.Lock()
        self.truth: list[tuple[TruthPose, NavProgress | None]] = []
        self.poses: list[PoseEstimate] = []
        self.progress: NavProgress | None = None
        bus.subscribe(keys.SIM_TRUTH, self._truth)
        bus.subscribe(keys.NAV_POSE, self._pose)
        bus.subscribe(keys.NAV_PROGRESS, self._progress)

    def _truth(self, t: TruthPose) -> None:
        with self.lock:
            self.truth.append((t, self.progress))

    def _pose(self, p: PoseEstimate) -> None:
        with self.lock:
            self.poses.append(p)

    def _progress(self, p: NavProgress) -> None:
        with self.lock:
            self.progress = p


def follow(bus: Bus, rec: Recorder, legs: list[Leg], route_id: str, timeout: float) -> NavState:
    deadline = time.monotonic() + 15
    while True:
        try:
            # an experiment watched by its operator: the longest lease, renewed below
            # (a slow profile drives the serpentine's 612 m for over an hour)
            route = FollowRoute(route_id=route_id, legs=legs, lease_s=LEASE_S)
            bus.call(keys.NAV_CMD, route, timeout=2)
            break
        except RpcError:
            if time.monotonic() > deadline:
                raise
    end = time.monotonic() + timeout
    renewed = time.monotonic()
    while time.monotonic() < end:
        if time.monotonic() - renewed > 30.0:  # 30 s of wall time: minutes of sim time
            with contextlib.suppress(RpcError):
                bus.call(keys.NAV_CMD, RenewRoute(route_id, LEASE_S), timeout=2)
            renewed = time.monotonic()
        p = rec.progress
        if (
            p is not None
            and p.route_id == route_id
            and p.state in (NavState.ARRIVED, NavState.BLOCKED, NavState.FAILED)
        ):
            return p.state
        time.sleep(0.2)
    raise TimeoutError(f"route {route_id} not finished within {timeout:.0f} s")
