"""Route following: straight legs tracked by pure pursuit, in-place rotations at the
corners (paper section 4.3), stops for obstacles and lost localization. Pure: the
service feeds it poses and times and sends out the velocities it returns.

The end of a route is a scan location, where the scanner's pose is what counts, so
the last leg ends with a *fine* phase (:mod:`services.nav.fine`); a sideways offset
there makes the robot back up along the leg and come in again (``BACKUP``).
"""

from __future__ import annotations

import math

from common.geo import wrap_angle
from common.messages.nav import ARRIVAL_TOLERANCE_M, LEASE_ENDED, Leg, NavState, legs_length
from services.nav.fine import Fine
from services.nav.follower_config import FollowerConfig
from services.nav.follower_types import Command, Phase, Tick
from services.nav.pursuit import (
    aim_at,
    along_remaining,
    cross_track,
    curvature,
    lookahead_point,
    predict,
    ramp,
    segment_distance,
)
from services.nav.turns import line_hold, turn_rate

__all__ = ["Command", "Follower", "FollowerConfig", "Phase"]


class Follower:
    def __init__(self, cfg: FollowerConfig) -> None:
        self.cfg = cfg
        self.legs: list[Leg] = []
        self.route_id = ""
        self.leg = 0
        self.phase = Phase.ALIGN
        self.state = NavState.IDLE
        self._v = 0.0
        self._w = 0.0
        self._t: float | None = None
        self._blocked_since: float | None = None
        self.speed_limit = cfg.max_speed
        self.fine = Fine(cfg)
        self._backup_to = 0.0  # distance behind the goal a back-up ends at (m)
        self.lease_until = math.inf
        self._join = False
        self.arrival_tolerance_m = ARRIVAL_TOLERANCE_M
        self.to_scan = True  # the route ends at a scan location (FollowRoute.to_scan)
        self.end_detail = ""  # how the last route ended (arrival or failure), for progress

    def start(
        self,
        route_id: str,
        legs: list[Leg],
        max_speed: float | None = None,
        lease_until: float = math.inf,
        join: bool = False,
        arrival_tolerance_m: float = ARRIVAL_TOLERANCE_M,
        to_scan: bool = True,
    ) -> None:
        """Follow ``legs`` until ``lease_until`` (seconds, the clock of :meth:`step`)
        unless renewed; with ``join``, start on the first leg passing within
        ``join_distance_m`` of the robot, decided at the first localized step (a
        restarted navigation is not localized yet when the route is sent again). It
        has arrived only within ``arrival_tolerance_m`` of its end (the route's own).
        ``to_scan``: it ends at a scan location (``FollowRoute.to_scan``)."""
        self.route_id, self.legs, self.leg = route_id, list(legs), 0
        self.lease_until, self._join = lease_until, join
        self.arrival_tolerance_m, self.end_detail, self.to_scan = arrival_tolerance_m, "", to_scan
        self.phase = Phase.ALIGN
        self.state = NavState.DRIVING if legs else NavState.ARRIVED
        self.fine = Fine(self.cfg)
        self.speed_limit = min(self.cfg.max_speed, max_speed or self.cfg.max_speed)
        self._blocked_since = None

    def renew(self, route_id: str, lease_until: float) -> bool:
        """Extend the lease of route ``route_id``; False when it is not this follower's
        route (navigation restarted, or another route replaced it), and the supervisor
        sends it again. A route that has ended stays renewable: its outcome is in the
        progress the supervisor reads."""
        if route_id != self.route_id:
            return False
        if self.active:
            self.lease_until = max(self.lease_until, lease_until)
        return True

    def abandon(self, why: str) -> None:
        """Stop the route now, as an expired lease does: its supervisor is gone."""
        if self.active:
            self.state, self.end_detail = NavState.FAILED, why

    def cancel(self) -> None:
        if self.state not in (NavState.IDLE, NavState.ARRIVED, NavState.BLOCKED):
            self.state = NavState.CANCELLED

    @property
    def active(self) -> bool:
        return self.state in (
            NavState.DRIVING,
            NavState.ROTATING,
            NavState.POSITIONING,
            NavState.WAITING_OBSTACLE,
            NavState.NOT_LOCALIZED,
        )

    def _rotate(self, err: float, dt: float) -> float:
        return turn_rate(err, self._w, self.cfg, dt)

    def _remaining(self, x: float, y: float) -> float:
        leg = self.legs[self.leg]
        rest = legs_length(self.legs[self.leg + 1 :])
        return max(0.0, along_remaining(x, y, leg.x0, leg.y0, leg.x1, leg.y1)) + rest

    def step(
        self,
        t: float,
        x: float,
        y: float,
        yaw: float,
        localized: bool,
        obstacle: bool,
        position_sd: float = 0.0,
        heading_sd: float = 0.0,
    ) -> Command:
        """The command for the pose estimate (x, y, yaw) at ``t`` (s);
        ``position_sd``: the estimate's position SD along its worse axis (m), which
        the fine phase's settle waits on; ``heading_sd`` (rad): no heading trim is
        finer than it. Each phase's handler returns its command, or None when the
        phase has ended and the next one takes the same step."""
        dt = 0.0 if self._t is None else max(0.0, min(t - self._t, 0.5))
        self._t = t
        self.fine.position_sd, self.fine.heading_sd = position_sd, heading_sd
        if not self.active or not self.legs:
            self._v = self._w = 0.0
            # how the route ended stays in every progress message after the end
            return Command(0.0, 0.0, self.state, self.leg, 0.0, 0.0, 0.0, "", self.end_detail)
        if self._join and localized and t <= self.lease_until:
            self._join = False
            near = [
                k
                for k, lg in enumerate(self.legs)
                if segment_distance(x, y, lg.x0, lg.y0, lg.x1, lg.y1) <= self.cfg.join_distance_m
            ]
            self.leg = near[0] if near else 0
        leg = self.legs[self.leg]
        heading = math.atan2(leg.y1 - leg.y0, leg.x1 - leg.x0)
        xte = cross_track(x, y, leg.x0, leg.y0, leg.x1, leg.y1)
        herr = wrap_angle(yaw - heading)
        k = Tick(t, dt, x, y, yaw, obstacle, leg, heading, xte, herr, self._remaining(x, y))
        if t > self.lease_until:
            return self._out(k, 0.0, 0.0, NavState.FAILED, "failed", f"{LEASE_ENDED}: not renewed")
        if not localized:
            return self._out(k, 0.0, 0.0, NavState.NOT_LOCALIZED)
        for phase, handle in (
            (Phase.ALIGN, self._align),
            (Phase.BACKUP, self._backup),
            (Phase.DRIVE, self._drive),
            (Phase.FINE, self._fine),
        ):
            if self.phase == phase and (c := handle(k)) is not None:
                return c
        return self._final(k)

    def _out(
        self, k: Tick, v: float, w: float, state: NavState, event: str = "", why: str = ""
    ) -> Command:
        self._v, self._w, self.state = v, w, state
        if why:
            self.end_detail = why
        return Command(v, w, state, self.leg, k.togo, k.xte, k.herr, event, why)

    def _align(self, k: Tick) -> Command | None:
        """Turn toward the leg's look-ahead point, held on its line, then drive."""
        aim = wrap_angle(k.yaw - aim_at(k.x, k.y, k.leg, self.cfg.lookahead_m))
        if k.leg.length <= self.cfg.goal_tolerance_m or abs(aim) <= math.radians(
            self.cfg.align_tolerance_deg
        ):
            self.phase = Phase.DRIVE
            return None
        v = line_hold(k.xte, k.herr, self.cfg)
        v = ramp(0.0 if k.obstacle and v > 0 else v, self._v, self.cfg.max_accel, k.dt)
        return self._out(k, v, self._rotate(-aim, k.dt), NavState.ROTATING)

    def _backup(self, k: Tick) -> Command | None:
        """Back up along the leg to come in again (the fine phase's re-approach)."""
        leg = k.leg
        if along_remaining(k.x, k.y, leg.x0, leg.y0, leg.x1, leg.y1) >= self._backup_to:
            self.phase = Phase.DRIVE
            return None
        # pure pursuit in reverse: steer the robot's back along the leg
        u = self.cfg.reapproach_speed
        px, py = lookahead_point(
            k.x, k.y, leg.x1, leg.y1, leg.x0, leg.y0, self.cfg.final_lookahead_m
        )
        c = curvature(k.x, k.y, wrap_angle(k.yaw + math.pi), px, py)
        w = max(-self.cfg.max_turn_rate, min(self.cfg.max_turn_rate, u * c))
        return self._out(k, -u, w, NavState.POSITIONING)

    def _drive(self, k: Tick) -> Command | None:
        """Pure pursuit along the leg, waiting for obstacles, to its end."""
        leg, cfg = k.leg, self.cfg
        last = self.leg + 1 == len(self.legs)
        if along_remaining(k.x, k.y, leg.x0, leg.y0, leg.x1, leg.y1) <= cfg.goal_tolerance_m:
            self.phase = Phase.FINE if last and cfg.fine and self.to_scan else Phase.FINAL
            self.fine.begin(k.t)
            return None
        if k.obstacle:
            self._blocked_since = self._blocked_since if self._blocked_since else k.t
            if k.t - self._blocked_since > cfg.obstacle_timeout_s:
                return self._out(k, 0.0, 0.0, NavState.BLOCKED, "blocked")
            return self._out(k, 0.0, 0.0, NavState.WAITING_OBSTACLE)
        self._blocked_since = None
        # the look-ahead runs past the leg's end, so the robot stays on the
        # line to the last centimetre instead of swerving at the goal point
        la = cfg.final_lookahead_m if last else cfg.lookahead_m
        qx, qy, qyaw = predict(k.x, k.y, k.yaw, self._v, self._w, cfg.predict_s)
        px, py = lookahead_point(qx, qy, leg.x0, leg.y0, leg.x1, leg.y1, la, beyond=True)
        c = curvature(qx, qy, qyaw, px, py)
        # slow down to stop at the leg's end (v^2 = 2 a d), where the robot
        # will be once the drivetrain has taken in this command
        ahead = along_remaining(qx, qy, leg.x0, leg.y0, leg.x1, leg.y1)
        v_stop = math.sqrt(2.0 * cfg.max_accel * 0.5 * max(0.0, ahead))
        v = min(self.speed_limit, max(cfg.min_speed, v_stop))
        v = ramp(v, self._v, cfg.max_accel, k.dt)
        w = max(-cfg.max_turn_rate, min(cfg.max_turn_rate, v * c))
        # coming in again after backing up is part of the fine positioning
        coming_in = self.fine.reapproaches > 0
        return self._out(k, v, w, NavState.POSITIONING if coming_in else NavState.DRIVING)

    def _fine(self, k: Tick) -> Command:
        """Fine positioning at the route's end (:mod:`services.nav.fine`)."""
        # the planned heading; a scan at the start point (zero-length leg, no
        # final_yaw) has none, and the robot scans as it stands. The position
        # comes first, on the leg's heading: a skid-steer robot creeps only along
        # its heading and backs up along the leg, so once turned to another
        # planned heading it could no longer correct its place along the leg
        leg, fine, tol = k.leg, self.fine, math.radians(self.cfg.heading_tolerance_deg)
        along = leg.length > 0
        final = leg.final_yaw if leg.final_yaw is not None else k.heading if along else k.yaw
        goal_yaw = final if fine.placed or not along else k.heading
        ferr = wrap_angle(k.yaw - goal_yaw)
        if abs(ferr) > tol and not fine.creeping:
            # a large turn (the leg's heading to another planned one) is done
            # coarsely first; the fine phase then settles and trims it
            fine.hold(k.t)
            return self._out(k, 0.0, self._rotate(-ferr, k.dt), NavState.ROTATING)
        if (
            along
            and abs(k.xte) > self.cfg.reapproach_tolerance_m
            and abs(k.herr) <= tol
            and fine.reapproach(k.t, k.xte)
        ):
            self.phase = Phase.BACKUP
            self._backup_to = min(self.cfg.reapproach_m, leg.length)
            self.speed_limit = min(self.speed_limit, self.cfg.reapproach_speed)
            return self._out(k, 0.0, 0.0, NavState.POSITIONING)
        # the robot can only creep along its heading: the goal's offset that way
        ahead = (leg.x1 - k.x) * math.cos(k.yaw) + (leg.y1 - k.y) * math.sin(k.yaw)
        placed = fine.placed
        # only a planned heading is trimmed to; the leg's own is held coarsely
        v, w = fine.step(k.t, ahead, ferr if leg.final_yaw is not None else None)
        if fine.placed != placed:
            return self._out(k, 0.0, 0.0, NavState.POSITIONING)  # the heading's turn next
        if v or w or not fine.settled(k.t):
            return self._out(k, v, w, NavState.POSITIONING)
        c = self._arrive(k, ferr)
        c.detail += f" ({fine.summary()})"
        self.end_detail = c.detail  # and in every progress message after it
        return c

    def _final(self, k: Tick) -> Command:
        """Rotate in place to the leg's final heading, then the next leg or the end."""
        leg = k.leg
        if leg.final_yaw is not None:
            ferr = wrap_angle(k.yaw - leg.final_yaw)
            if abs(ferr) > math.radians(self.cfg.heading_tolerance_deg):
                return self._out(k, 0.0, self._rotate(-ferr, k.dt), NavState.ROTATING)
        if self.leg + 1 < len(self.legs):
            self.leg += 1
            self.phase = Phase.ALIGN
            return self._out(k, 0.0, 0.0, NavState.DRIVING)
        yaw_goal = leg.final_yaw if leg.final_yaw is not None else k.heading
        return self._arrive(k, wrap_angle(k.yaw - yaw_goal) if leg.length > 0 else 0.0)

    def _arrive(self, k: Tick, yaw_err: float) -> Command:
        """ARRIVED when the estimate is within the route's arrival tolerances (a route
        not to a scan: its distance only), else FAILED, saying how far off."""
        leg = self.legs[-1]
        off = math.hypot(leg.x1 - k.x, leg.y1 - k.y)
        what = f"{1000 * off:.1f} mm and {math.degrees(yaw_err):+.2f} deg off the planned pose"
        heading_ok = abs(yaw_err) <= math.radians(self.cfg.arrival_heading_tolerance_deg)
        if off <= self.arrival_tolerance_m and (heading_ok or not self.to_scan):
            return self._out(k, 0.0, 0.0, NavState.ARRIVED, "arrived", f"{what} by the estimate")
        return self._out(k, 0.0, 0.0, NavState.FAILED, "failed", f"stopped {what}")
