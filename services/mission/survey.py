"""The survey loop: drive to each location, check the pose, scan, record, go on.

Every wait has a deadline on the mission's clock and wakes at once on abort or stop.
Routes are leased: the loop renews its route while it waits, so a mission that dies
stops the robot, and a navigation that restarted (it no longer knows the route) gets
the route again, joined where the robot stands. A scan is taken only where the pose
estimate is within ``arrival_tolerance_m`` of the planned location, checked before
every attempt (a resumed one included), and recorded ``done`` only where the robot
stood still over it within ``scan_tolerance_m``. An RPC that times out (its service
restarting, or slow on a loaded machine) is retried for ``rpc_patience_s``; only an
error reply or that much silence fails.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable
from typing import TypeVar

from common import clock as clk
from common import keys
from common.clock import NS
from common.keys import Rpc
from common.messages.nav import (
    LEASE_ENDED,
    CancelRoute,
    FollowRoute,
    NavReply,
    NavState,
    PoseEstimate,
    RenewRoute,
    legs_length,
)
from common.missionlog import Step
from common.service import Context
from common.transport import RpcError, RpcTimeout
from services.mission.config import MissionConfig
from services.mission.feeds import Aborted, Feeds
from services.mission.lanes import Lanes
from services.mission.log import MissionLog
from services.mission.plan import Segment
from services.mission.scanning import Scans
from services.mission.standing import settle

Q = TypeVar("Q")
R = TypeVar("R")
SKEW_NS = NS // 5


class Survey:
    """Runs one mission's steps. ``wake`` is set on abort and on stop; ``abort`` and
    ``paused`` are the operator's; ``event(level, text)`` reports."""

    def __init__(
        self,
        ctx: Context,
        cfg: MissionConfig,
        feeds: Feeds,
        log: MissionLog,
        mission: str,
        event: Callable[[str, str], None],
        wake: threading.Event,
        abort: threading.Event,
        paused: threading.Event,
        lanes: Lanes | None = None,
    ) -> None:
        self.ctx, self.cfg, self.log, self.event = ctx, cfg, log, event
        self.lanes = lanes  # the reservations with robots sharing the field, if any
        self.give_way = False  # on a deadlock, raise GiveWay (the walk has elsewhere to go)
        self.mission = mission
        self.wake, self.abort, self.paused = wake, abort, paused
        self.pose, self.progress, self.scanner = feeds.pose, feeds.progress, feeds.scanner
        self.battery = feeds.battery
        self._lock = threading.Lock()
        self._collect: list[PoseEstimate] | None = None
        self._last_pose: PoseEstimate | None = None
        self._pose_at = self.now()  # when the newest pose arrived, on this clock
        self.distance = 0.0  # metres driven since this survey (or its resumption) began
        feeds.on_pose = self._on_pose  # the previous survey, ended, hears no more
        self.detail = ""
        self._routes = 0
        self.scans = Scans(self)

    def _on_pose(self, p: PoseEstimate) -> None:
        at = self.now()
        with self._lock:
            self._pose_at = max(self._pose_at, at)
            if self._collect is not None:
                self._collect.append(p)
            # distance driven, measured: the estimate's speed (odometry-borne, zero
            # at rest through the zero-velocity updates) over time, not the plan's legs
            if self._last_pose is not None and p.stamp_ns > self._last_pose.stamp_ns:
                dt = min((p.stamp_ns - self._last_pose.stamp_ns) / NS, 1.0)
                self.distance += abs(p.v) * dt
            self._last_pose = p

    def pose_age_s(self) -> float:
        """How long since navigation last said where the robot is, on this clock: the
        newest pose held says nothing of a navigation that has since hung."""
        with self._lock:
            return (self.now() - self._pose_at) / NS

    def collect(self, poses: list[PoseEstimate] | None) -> None:
        """Collect every pose from now on after ``poses`` (None: stop collecting)."""
        with self._lock:
            self._collect = poses

    def collected(self) -> list[PoseEstimate]:
        """The poses collected so far; collection stops."""
        with self._lock:
            poses, self._collect = self._collect or [], None
        return poses

    def now(self) -> int:
        return self.ctx.clock.now_ns()

    # --- waiting and calling ---
    def wait(self, seconds: float) -> int:
        """Wait ``seconds`` on the clock, and while paused; returns the time spent
        paused (ns), for deadlines that must not count it. Raises Aborted."""
        self.sleep(seconds)
        t0 = self.now()
        while self.paused.is_set():
            self.sleep(0.5)
        return self.now() - t0

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` on the clock, paused or not. Raises Aborted."""
        if not clk.sleep(self.ctx.clock, seconds, self.wake):
            raise Aborted

    def call(self, rpc: Rpc[Q, R], req: Q) -> R:
        """``rpc`` answered, retried while its service is silent (restarting) for up
        to ``rpc_patience_s`` of wall time. Raises RpcError on an error reply or on
        that much silence, Aborted on abort or stop."""
        deadline = time.monotonic() + self.cfg.rpc_patience_s
        warned = False
        while True:
            try:
                return self.ctx.bus.call(rpc, req, timeout=self.cfg.rpc_timeout_s)
            except RpcTimeout:
                if time.monotonic() > deadline:
                    raise
                if not warned:
                    self.event("warning", f"{rpc.key}: no answer, retrying")
                    warned = True
            if self.wake.wait(0.5):
                raise Aborted

    # --- driving ---
    def drive(self, seg: Segment, route_id: str) -> tuple[bool, str]:
        """Follow ``seg`` (joined where the robot stands), its lanes reserved first
        when robots share the field; (arrived, why not)."""
        length = legs_length(seg.legs)
        limit_ns = int((self.cfg.route_time_s + length / self.cfg.route_min_speed) * NS)
        if self.lanes is not None:
            say = lambda text: self.event("info", text)  # noqa: E731
            self.lanes.reserve(seg.legs, self.wait, say, give_way=self.give_way)
        why = ""
        for attempt in range(self.cfg.blocked_retries + 1):
            # every route sent gets a new id: navigation keeps publishing an ended
            # route's outcome, which must never be taken for a later route's
            self._routes += 1
            rid = f"{route_id}.{self._routes}"
            ok, why = self._follow(seg, rid, limit_ns)
            if ok:
                if self.lanes is not None:
                    x, y, _ = seg.end
                    self.lanes.release_to(x, y)
                return True, ""
            self.event("warning", f"{route_id}: {why} (attempt {attempt + 1})")
        return False, why

    def _send(self, seg: Segment, rid: str) -> int:
        """Send the route; the clock time it was sent at. A route to a scan location
        must arrive within ``arrival_tolerance_m`` after fine positioning; one to the
        Origin (home, a swap: no location) within ``origin_radius_m``, without it."""
        to_scan = seg.cand_id is not None
        route = FollowRoute(
            route_id=rid,
            legs=seg.legs,
            lease_s=self.cfg.lease_s,
            join=True,
            arrival_tolerance_m=self.cfg.arrival_tolerance_m
            if to_scan
            else self.cfg.origin_radius_m,
            to_scan=to_scan,
        )
        sent = self.now()
        rep: NavReply = self.call(keys.NAV_CMD, route)
        if not rep.accepted:
            raise RpcError(f"navigation refused route {rid}: {rep.reason}")
        return sent

    def _follow(self, seg: Segment, route_id: str, limit_ns: int) -> tuple[bool, str]:
        rid = route_id
        sent = renewed = t0 = self._send(seg, rid)
        warned, pauses = False, 0
        while True:
            if self.paused.is_set():
                # a pause stops the robot now, not when the lease runs out (metres
                # later): the route is cancelled, and sent again from where the robot
                # stands once resumed, under an id of its own (the cancelled route's
                # outcome must not be taken for it)
                self.cancel(rid)
                t0 += self.wait(0.0)
                pauses += 1
                rid = f"{route_id}.p{pauses}"
                sent = renewed = self._send(seg, rid)
                continue
            self.sleep(0.1)  # not wait(): a pause is seen above, while driving
            now = self.now()
            if now - t0 > limit_ns:
                self.cancel(rid)
                return False, f"no arrival in {limit_ns / NS:.0f} s"
            p = self.progress.get()
            # progress of this route since it was (last) sent; services on a sim clock
            # follow it a tick or two apart
            if p is not None and p.route_id == rid and p.stamp_ns >= sent - SKEW_NS:
                self._passed(p.leg, seg)
                if p.state == NavState.ARRIVED:
                    # how it got there (how far off by the estimate, the fine phase's
                    # moves) stays in the mission log
                    self.event(
                        "info", f"{rid}: arrived: {p.detail}" if p.detail else f"{rid}: arrived"
                    )
                    return True, ""
                if p.state == NavState.BLOCKED:
                    return False, "navigation blocked"
                if p.state == NavState.FAILED and not p.detail.startswith(LEASE_ENDED):
                    return False, f"navigation failed: {p.detail}"
                if p.state == NavState.FAILED and p.stamp_ns > sent + SKEW_NS:
                    # held up past the lease (paused, say); a FAILED stamped about when
                    # the route was last sent may be the one that resent it
                    self.event("warning", f"{rid}: lease ran out, sending the route again")
                    sent = renewed = self._send(seg, rid)
                    continue
                lost = p.state == NavState.NOT_LOCALIZED
                if lost != warned:
                    text = "lost, waiting" if lost else "back"
                    self.event("warning" if lost else "info", f"{rid}: localization {text}")
                    warned = lost
            if (now - renewed) / NS >= self.cfg.lease_s / 4:
                rep: NavReply = self.call(keys.NAV_CMD, RenewRoute(rid, self.cfg.lease_s))
                renewed = self.now()
                if not rep.accepted:  # navigation restarted and forgot the route
                    self.event("warning", f"{rid}: {rep.reason}; sending it again")
                    sent = renewed = self._send(seg, rid)

    def _passed(self, leg: int, seg: Segment) -> None:
        """What the robot's lanes behind it are (robots sharing the field)."""
        pose = self.pose.get()
        if self.lanes is not None and pose is not None and 0 <= leg < len(seg.legs):
            self.lanes.passed(leg, seg.legs, pose.x, pose.y)

    def cancel(self, rid: str = "") -> None:
        """Stop route ``rid`` now, or whatever route navigation follows when ``rid``
        is empty (an abort does not know which of its resends is running)."""
        with contextlib.suppress(RpcError):  # the lease stops the robot anyway
            self.ctx.bus.call(keys.NAV_CMD, CancelRoute(route_id=rid), timeout=2.0)

    # --- at a location ---
    def settle(self) -> PoseEstimate | None:
        """:func:`services.mission.standing.settle` on this survey."""
        return settle(self)

    def off_by(self, step: Step, x: float, y: float) -> float:
        return math.hypot(x - step.x, y - step.y)

    def position(self, step: Step, seg: Segment, tag: str, drive_first: bool) -> str:
        """Bring the robot to ``step``'s location and hold it still there; "" when it
        is, else why not."""
        for attempt in range(self.cfg.position_retries + 1):
            if drive_first or attempt > 0:
                self.detail = f"to {tag}"
                ok, why = self.drive(seg, f"{self.mission}.{step.scan_id}.{attempt}")
                if not ok:
                    return why
            self.detail = tag
            p = self.settle()
            if p is None:
                return f"not localized and still within {self.cfg.settle_timeout_s:.0f} s"
            off = self.off_by(step, p.x, p.y)
            if off <= self.cfg.arrival_tolerance_m:
                return ""
            self.event("warning", f"{tag}: {100 * off:.1f} cm from the planned location")
            drive_first = True
        return f"still {100 * off:.1f} cm off after {self.cfg.position_retries + 1} tries"
