"""What ``phenorover nav-test`` records of a run (truth, estimates, progress), and the
route it has navigation follow, leased and renewed."""

from __future__ import annotations

import bisect
import contextlib
import threading
import time
from collections.abc import Callable

from common import keys
from common.messages.nav import FollowRoute, Leg, NavProgress, NavState, PoseEstimate, RenewRoute
from common.messages.sim import TruthPose
from common.transport import Bus, RpcError

ENDED = (NavState.ARRIVED, NavState.BLOCKED, NavState.FAILED)
LEASE_S = 3600.0  # the longest a route may be leased for (FollowRoute.lease_s)


Release = Callable[[], object] | None  # lets a held world run (lockstep), if any
# the slowest a world in lockstep is taken to go (x real time), for deadlines: the
# border experiment ran 190 s of sim time in 38 s of wall time, start-up included,
# and the serpentine about 5x
LOCKSTEP_PACE = 4.0


def pace(rtf: float, release: Release) -> float:
    """The world's pace (x real time) to set a wall-time deadline by: ``rtf``, which in
    lockstep (``release`` given) is only a cap."""
    return min(rtf, LOCKSTEP_PACE) if release is not None else rtf


class Recorder:
    """Truth, estimates and progress, as they arrive."""

    def __init__(self, bus: Bus) -> None:
        self.lock = threading.Lock()
        self.truth: list[TruthPose] = []
        self.poses: list[PoseEstimate] = []
        self.progress: NavProgress | None = None
        self._progress_log: list[NavProgress] = []
        bus.subscribe(keys.SIM_TRUTH, self._truth)
        bus.subscribe(keys.NAV_POSE, self._pose)
        bus.subscribe(keys.NAV_PROGRESS, self._progress)

    def _truth(self, t: TruthPose) -> None:
        with self.lock:
            self.truth.append(t)

    def _pose(self, p: PoseEstimate) -> None:
        with self.lock:
            self.poses.append(p)

    def _progress(self, p: NavProgress) -> None:
        with self.lock:
            self.progress = p
            self._progress_log.append(p)

    def paired(self, route_id: str) -> list[tuple[TruthPose, NavProgress]]:
        """Each true pose taken while navigation followed ``route_id``, up to its end
        (arrived, blocked or failed), with the progress it had stamped by then: paired
        by the sim clock's stamps, not by which of two messages of one instant arrived
        first, and ending where the route did, not where this process stopped
        listening (in lockstep the same seed then gives the same pairs)."""
        with self.lock:
            log = sorted(self._progress_log, key=lambda p: p.stamp_ns)
            truth = list(self.truth)
        stamps = [p.stamp_ns for p in log]
        out = []
        for t in truth:
            k = bisect.bisect_right(stamps, t.stamp_ns) - 1
            if k >= 0 and log[k].route_id == route_id:
                out.append((t, log[k]))
                if log[k].state in ENDED:
                    break
        return out


def follow(
    bus: Bus,
    rec: Recorder,
    legs: list[Leg],
    route_id: str,
    timeout: float,
    release: Release = None,
) -> NavProgress:
    """Send the route, then ``release`` a held world (lockstep), and wait for the
    route's end: its last progress (ARRIVED, BLOCKED or FAILED, and why)."""
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
    if release is not None:
        release()
    end = time.monotonic() + timeout
    renewed = time.monotonic()
    while time.monotonic() < end:
        if time.monotonic() - renewed > 30.0:  # 30 s of wall time: minutes of sim time
            with contextlib.suppress(RpcError):
                bus.call(keys.NAV_CMD, RenewRoute(route_id, LEASE_S), timeout=2)
            renewed = time.monotonic()
        p = rec.progress
        if p is not None and p.route_id == route_id and p.state in ENDED:
            return p
        time.sleep(0.2)
    raise TimeoutError(f"route {route_id} not finished within {timeout:.0f} s")
