"""Fine positioning at a scan location, the route's end (pure; times in seconds).

The robot stands ``fine_settle_s``, longer while the estimate's position SD is above
``fine_settle_sd_m`` (at most ``fine_settle_max_s``: the filter averages GNSS while
the wheels are still), then creeps along its heading to within ``fine_tolerance_m``
of the goal, re-checking ``fine_resettle_s`` after each move. A creep slows as it
nears the goal and ends at ``creep_speed``, low enough that the drivetrain's lag
overshoots by well under the tolerances.

Only where the route plans a heading at its end does the robot then turn slowly to
within ``fine_heading_tolerance_deg`` of it, or of the estimate's own heading SD if
that is larger: under the crop the compass wanders by more than the tolerance, and
each trim is a turn in place, which shifts a skid-steer robot sideways. A scan
location plans none (a 360 deg scan does not care), so there the robot keeps the
heading it came in with. The place comes first: a skid-steer robot creeps only along
its heading, so once turned to another planned heading it could no longer correct
its place along the leg. A sideways offset, which no creep removes, is the
follower's to drive out by backing up (:meth:`Fine.reapproach` says whether the
budget allows one).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from services.nav.follower_config import FollowerConfig

# a creep along the leg goes at its remaining distance over this (s), within
# creep_speed..creep_max_speed: it slows to creep_speed over its last centimetres
CREEP_S = 1.0


def pose_sds(cov: npt.NDArray[np.float64]) -> tuple[float, float]:
    """The SDs the fine phase works to, from the (x, y, yaw) covariance: the
    position's along its worse axis (m) and the heading's (rad); both unknown, as inf,
    when the covariance is not finite, so the settle waits and no trim is made."""
    if not np.isfinite(cov).all():
        return math.inf, math.inf
    var = float(np.linalg.eigvalsh(cov[:2, :2])[-1])
    return math.sqrt(max(var, 0.0)), math.sqrt(max(float(cov[2, 2]), 0.0))


class Fine:
    """The fine phase's budget of moves and its timers, for one route."""

    def __init__(self, cfg: FollowerConfig) -> None:
        self.cfg = cfg
        self.moves = 0  # creeps along the heading, re-approaches included
        self.turns = 0  # heading trims
        self.reapproaches = 0
        self.placed = False  # the place is done: the heading follows
        self._creep: tuple[str, float] | None = None  # ("v" | "w", sign) while creeping
        self._still_since = 0.0
        self._settle = cfg.fine_settle_s  # how long to stand before the next check
        self._arriving = False  # this settle is an arrival's: it waits for the estimate
        self.position_sd = 0.0  # the estimate's, m (the follower's caller keeps it)
        self.heading_sd = 0.0  # and its heading's, rad
        self.waited = 0.0  # how long the last arrival's settle took, s
        self.settled_sd = 0.0  # and the position SD it ended at, m
        self.history: list[str] = []  # each move, for the arrival's detail

    def begin(self, t: float) -> None:
        """The robot stopped at the goal (first, or after coming in again): stand
        ``fine_settle_s`` before the first check."""
        self._still_since, self._settle = t, self.cfg.fine_settle_s
        self._arriving = True

    def hold(self, t: float) -> None:
        """The robot is turning coarsely: the settle starts again once it stops."""
        self._still_since = t

    @property
    def creeping(self) -> bool:
        return self._creep is not None

    def settled(self, t: float) -> bool:
        waited = t - self._still_since
        if waited < self._settle:
            return False
        if self._arriving:
            c = self.cfg
            if self.position_sd > c.fine_settle_sd_m and waited < c.fine_settle_max_s:
                return False
            self._arriving, self.waited, self.settled_sd = False, waited, self.position_sd
        return True

    def reapproach(self, t: float, aside: float = 0.0) -> bool:
        """Whether to back up and come in again now (settled, not creeping, budget
        left), ``aside`` metres off the leg; counts it when so."""
        c = self.cfg
        ok = (
            self._creep is None
            and self.settled(t)
            and self.reapproaches < c.reapproaches
            and self.moves < c.fine_moves
        )
        if ok:
            self.reapproaches += 1
            self.moves += 1
            self.history.append(f"re-approach {1000 * aside:+.0f} mm aside")
        return ok

    def summary(self) -> str:
        """What the fine phase did: its moves in order, and its last arrival's settle."""
        moves = f"{', '.join(self.history)}; " if self.history else "no move; "
        return (
            f"{moves}the last settle {self.waited:.0f} s, to a position SD of "
            f"{1000 * self.settled_sd:.1f} mm"
        )

    def step(self, t: float, rem: float, yaw_err: float | None) -> tuple[float, float]:
        """One step at the goal, ``rem`` metres short of it along the robot's heading
        and ``yaw_err`` off the heading sought (None: no heading is sought, none is
        trimmed): (v, w) to creep with, or (0, 0) to stand (settling, or done)."""
        c = self.cfg
        if self._creep is not None:
            kind, sign = self._creep
            err = rem if kind == "v" else -(yaw_err or 0.0)
            # a creep slows as it nears the goal (its distance per second), so it
            # ends at creep_speed however far it began
            rate = (
                min(c.creep_max_speed, max(c.creep_speed, abs(err) / CREEP_S))
                if kind == "v"
                else c.creep_turn_rate
            )
            # aim at the goal itself, stopping early by what is still in the pipeline
            if sign * err > rate * c.creep_latency_s:
                return (sign * rate, 0.0) if kind == "v" else (0.0, sign * rate)
            self._creep, self._still_since, self._settle = None, t, c.fine_resettle_s
            return 0.0, 0.0
        if not self.settled(t):
            return 0.0, 0.0
        # position and heading each have their own budget of moves: a trim of the
        # heading is cheap and must not go short because the position took long
        if abs(rem) > c.fine_tolerance_m and self.moves < c.fine_moves:
            self._creep = ("v", math.copysign(1.0, rem))
            self.moves += 1
            self.history.append(f"creep {1000 * rem:+.0f} mm")
        elif not self.placed:
            self.placed = True
            return 0.0, 0.0
        elif (
            yaw_err is not None
            and abs(yaw_err) > max(math.radians(c.fine_heading_tolerance_deg), self.heading_sd)
            and self.turns < c.fine_moves
        ):
            self._creep = ("w", math.copysign(1.0, -yaw_err))
            self.turns += 1
            self.history.append(f"trim {math.degrees(-yaw_err):+.2f} deg")
        else:
            return 0.0, 0.0
        return self.step(t, rem, yaw_err)
