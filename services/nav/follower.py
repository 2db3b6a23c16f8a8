"""Route following: straight legs tracked by pure pursuit, in-place rotations at the
corners (paper section 4.3), stops for obstacles and lost localization. Pure: the
service feeds it poses and times and sends out the velocities it returns.

The end of a route is a scan location, where the scanner's pose is what counts, so
the last leg ends with a *fine* phase (:mod:`services.nav.fine`); a sideways offset
there makes the robot back up along the leg and come in again (``BACKUP``).
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Callable

from common.geo import wrap_angle
from common.messages.nav import LEASE_ENDED, Leg, NavState
from services.nav.fine import Fine
from services.nav.follower_config import FollowerConfig
from services.nav.pursuit import (
    aim_at,
    along_remaining,
    cross_track,
    curvature,
    lookahead_point,
    predict,
    segment_distance,
)

__all__ = ["Command", "Follower", "FollowerConfig", "Phase"]


class Phase(enum.Enum):
    ALIGN = "align"
    DRIVE = "drive"
    FINAL = "final"
    FINE = "fine"
    BACKUP = "backup"


@dataclasses.dataclass
class Command:
    v: float
    w: float
    state: NavState
    leg: int
    distance_to_go: float
    cross_track: float
    heading_error: float
    event: str = ""  # set once when the route ends: arrived, blocked
    detail: str = ""  # with an event: how it ended, for the log


def _leg_len(leg: Leg) -> float:
    return math.hypot(leg.x1 - leg.x0, leg.y1 - leg.y0)


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
        self.end_detail = ""  # how the last route ended (arrival or failure), for progress

    def start(
        self,
        route_id: str,
        legs: list[Leg],
        max_speed: float | None = None,
        lease_until: float = math.inf,
        join: bool = False,
    ) -> None:
        """Follow ``legs`` until ``lease_until`` (seconds, the clock of :meth:`step`)
        unless renewed; with ``join``, start on the first leg passing within
        ``join_distance_m`` of the robot, decided at the first localized step (a
        restarted navigation is not localized yet when the route is sent again)."""
        self.route_id, self.legs, self.leg = route_id, list(legs), 0
        self.lease_until = lease_until
        self._join = join
        self.end_detail = ""
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

    def _ramp(self, target: float, current: float, rate: float, dt: float) -> float:
        return current + max(-rate * dt, min(rate * dt, target - current))

    def _rotate(self, err: float, dt: float) -> float:
        """The turn rate toward a heading ``err`` rad away (see FollowerConfig)."""
        c = self.cfg
        brake = math.sqrt(2.0 * c.turn_braking * c.max_turn_accel * abs(err))
        w = max(c.min_turn_rate, min(c.max_turn_rate, c.rotate_gain * abs(err), brake))
        return self._ramp(math.copysign(w, err), self._w, c.max_turn_accel, dt)

    def _remaining(self, x: float, y: float) -> float:
        leg = self.legs[self.leg]
        rest = sum(_leg_len(lg) for lg in self.legs[self.leg + 1 :])
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
        finer than it."""
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
        togo = self._remaining(x, y)

        def out(v: float, w: float, state: NavState, event: str = "", why: str = "") -> Command:
            self._v, self._w, self.state = v, w, state
            if why:
                self.end_detail = why
            return Command(v, w, state, self.leg, togo, xte, herr, event, why)

        if t > self.lease_until:
            return out(0.0, 0.0, NavState.FAILED, "failed", f"{LEASE_ENDED}: not renewed")
        if not localized:
            return out(0.0, 0.0, NavState.NOT_LOCALIZED)
        tol = math.radians(self.cfg.heading_tolerance_deg)
        align = math.radians(self.cfg.align_tolerance_deg)
        if self.phase == Phase.ALIGN:
            aim = wrap_angle(yaw - aim_at(x, y, leg, self.cfg.lookahead_m))
            if _leg_len(leg) <= self.cfg.goal_tolerance_m or abs(aim) <= align:
                self.phase = Phase.DRIVE
            else:
                return out(0.0, self._rotate(-aim, dt), NavState.ROTATING)
        if self.phase == Phase.BACKUP:
            if along_remaining(x, y, leg.x0, leg.y0, leg.x1, leg.y1) < self._backup_to:
                # pure pursuit in reverse: steer the robot's back along the leg
                u = self.cfg.reapproach_speed
                px, py = lookahead_point(
                    x, y, leg.x1, leg.y1, leg.x0, leg.y0, self.cfg.final_lookahead_m
                )
                k = curvature(x, y, wrap_angle(yaw + math.pi), px, py)
                w = max(-self.cfg.max_turn_rate, min(self.cfg.max_turn_rate, u * k))
                return out(-u, w, NavState.POSITIONING)
            self.phase = Phase.DRIVE
        if self.phase == Phase.DRIVE:
            rem = along_remaining(x, y, leg.x0, leg.y0, leg.x1, leg.y1)
            if rem > self.cfg.goal_tolerance_m:
                if obstacle:
                    self._blocked_since = self._blocked_since if self._blocked_since else t
                    if t - self._blocked_since > self.cfg.obstacle_timeout_s:
                        return out(0.0, 0.0, NavState.BLOCKED, "blocked")
                    return out(0.0, 0.0, NavState.WAITING_OBSTACLE)
                self._blocked_since = None
                # the look-ahead runs past the leg's end, so the robot stays on the
                # line to the last centimetre instead of swerving at the goal point
                last = self.leg + 1 == len(self.legs)
                la = self.cfg.final_lookahead_m if last else self.cfg.lookahead_m
                qx, qy, qyaw = predict(x, y, yaw, self._v, self._w, self.cfg.predict_s)
                px, py = lookahead_point(qx, qy, leg.x0, leg.y0, leg.x1, leg.y1, la, beyond=True)
                k = curvature(qx, qy, qyaw, px, py)
                # slow down to stop at the leg's end (v^2 = 2 a d), where the robot
                # will be once the drivetrain has taken in this command
                ahead = along_remaining(qx, qy, leg.x0, leg.y0, leg.x1, leg.y1)
                v_stop = math.sqrt(2.0 * self.cfg.max_accel * 0.5 * max(0.0, ahead))
                v = min(self.speed_limit, max(self.cfg.min_speed, v_stop))
                v = self._ramp(v, self._v, self.cfg.max_accel, dt)
                w = max(-self.cfg.max_turn_rate, min(self.cfg.max_turn_rate, v * k))
                # coming in again after backing up is part of the fine positioning
                coming_in = self.fine.reapproaches > 0
                return out(v, w, NavState.POSITIONING if coming_in else NavState.DRIVING)
            last = self.leg + 1 == len(self.legs)
            self.phase = Phase.FINE if last and self.cfg.fine else Phase.FINAL
            self.fine.begin(t)
        if self.phase == Phase.FINE:
            # the planned heading; a scan at the start point (zero-length leg, no
            # final_yaw) has none, and the robot scans as it stands. The position
            # comes first, on the leg's heading: a skid-steer robot creeps only along
            # its heading and backs up along the leg, so once turned to another
            # planned heading it could no longer correct its place along the leg
            along = _leg_len(leg) > 0
            final = leg.final_yaw if leg.final_yaw is not None else heading if along else yaw
            goal_yaw = final if self.fine.placed or not along else heading
            ferr = wrap_angle(yaw - goal_yaw)
            fine = self.fine
            if abs(ferr) > tol and not fine.creeping:
                # a large turn (the leg's heading to another planned one) is done
                # coarsely first; the fine phase then settles and trims it
                fine.hold(t)
                return out(0.0, self._rotate(-ferr, dt), NavState.ROTATING)
            if (
                along
                and abs(xte) > self.cfg.reapproach_tolerance_m
                and abs(herr) <= tol
                and fine.reapproach(t, xte)
            ):
                self.phase = Phase.BACKUP
                self._backup_to = min(self.cfg.reapproach_m, _leg_len(leg))
                self.speed_limit = min(self.speed_limit, self.cfg.reapproach_speed)
                return out(0.0, 0.0, NavState.POSITIONING)
            # the robot can only creep along its heading: the goal's offset that way
            ahead = (leg.x1 - x) * math.cos(yaw) + (leg.y1 - y) * math.sin(yaw)
            placed = fine.placed
            # only a planned heading is trimmed to; the leg's own is held coarsely
            v, w = fine.step(t, ahead, ferr if leg.final_yaw is not None else None)
            if fine.placed != placed:
                return out(0.0, 0.0, NavState.POSITIONING)  # the heading's turn next
            if v or w or not fine.settled(t):
                return out(v, w, NavState.POSITIONING)
            c = self._arrive(out, x, y, ferr)
            c.detail += f" ({fine.summary()})"
            self.end_detail = c.detail  # and in every progress message after it
            return c
        # FINAL: rotate in place to the next leg's heading
        if leg.final_yaw is not None:
            ferr = wrap_angle(yaw - leg.final_yaw)
            if abs(ferr) > tol:
                return out(0.0, self._rotate(-ferr, dt), NavState.ROTATING)
        if self.leg + 1 < len(self.legs):
            self.leg += 1
            self.phase = Phase.ALIGN
            return out(0.0, 0.0, NavState.DRIVING)
        yaw_goal = leg.final_yaw if leg.final_yaw is not None else heading
        return self._arrive(out, x, y, wrap_angle(yaw - yaw_goal) if _leg_len(leg) > 0 else 0.0)

    def _arrive(self, out: Callable[..., Command], x: float, y: float, yaw_err: float) -> Command:
        """ARRIVED when the estimate is within the arrival tolerances of the route's
        end, FAILED (saying how far off) otherwise."""
        leg = self.legs[-1]
        off = math.hypot(leg.x1 - x, leg.y1 - y)
        what = f"{1000 * off:.1f} mm and {math.degrees(yaw_err):+.2f} deg off the planned pose"
        if off <= self.cfg.arrival_tolerance_m and abs(yaw_err) <= math.radians(
            self.cfg.arrival_heading_tolerance_deg
        ):
            return out(0.0, 0.0, NavState.ARRIVED, "arrived", f"{what} by the estimate")
        return out(0.0, 0.0, NavState.FAILED, "failed", f"stopped {what}")
