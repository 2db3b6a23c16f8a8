"""Localization: an extended Kalman filter in the ``field`` frame, fusing
wheel odometry, both GNSS antenna positions (through their lever arms) and the
GNSS-compass heading, as robot_localization does for the paper's robot.

State ``[x, y, yaw, v, w]`` (metres, radians, m/s, rad/s) of base_link; a unicycle
with constant velocities between measurements. Pure: times in seconds, no I/O.

Refused (counted in ``counters.rejected_by`` under the kind): ``invalid``, a value
not finite or absurd, or a (co)variance zero, negative, not finite or not positive
semi-definite (:mod:`services.nav.ekf_guard`); ``stamp``, a stamp further than
``max_stamp_skew_s`` from the filter's time; ``gate``, a measurement beyond the
chi-square 99.9 % gate of the estimate, so a multipath jump is not followed.

Recovered (``counters.resets_by``): ``reset_after`` gated rejections in a row that
agree with each other mean the filter is wrong, not the sensor: the states they
observe are re-initialised from them (``relocalized``); as many stamped alike ahead
of the filter's time move it there (``time``). A state that is ever non-finite
(``nonfinite``) or beyond what the robot can be (``implausible``) resets the filter
to not localized; the next fix initialises it again. No update method raises on bad
input: each returns whether it fused, ``counters.last_reason`` says why not.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from common.arrays import F64
from common.geo import wrap_angle
from services.nav.ekf_config import EkfConfig
from services.nav.ekf_guard import (
    ConsistentRun,
    Counters,
    StampGuard,
    check_antenna,
    check_heading,
    check_height,
    check_odometry,
    eigenvalues_2x2,
    state_problem,
)
from services.nav.ekf_models import (
    HeightFilter,
    antenna_model,
    motion_share,
    process_noise,
    unicycle,
)

__all__ = ["CHI2_999", "EkfConfig", "Localizer"]


# chi-square 99.9 % quantiles for 1, 2, 3 degrees of freedom
CHI2_999 = {1: 10.83, 2: 13.82, 3: 16.27}


def _angle_residual(a: F64, b: F64) -> F64:
    y = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    y[0] = wrap_angle(float(y[0]))
    return y


def _subtract(a: F64, b: F64) -> F64:
    return np.asarray(a, dtype=float) - np.asarray(b, dtype=float)


class Localizer:
    """The filter; ``counters`` says what it refused and reset (for health)."""

    def __init__(self, cfg: EkfConfig) -> None:
        self.cfg = cfg
        self.t: float | None = None
        self.counters = Counters()
        self._stamps = StampGuard(cfg.max_stamp_skew_s, cfg.reset_after)
        self._clear()

    def _clear(self) -> None:
        """Forget everything but the time: not localized, waiting for a first fix."""
        self._x = np.zeros(5)
        self._p = np.diag([1e4, 1e4, math.pi**2, 1.0, 1.0])
        self._runs: dict[str, ConsistentRun] = {}
        self._have_heading = False
        self._have_position = False
        self._blind = False  # the position was set before any heading: lever unknown
        self._still = False  # the last odometry was a zero-velocity update
        self._last_t: dict[str, float] = {}  # stamp of each kind's last measurement
        self.height = HeightFilter()

    @property
    def initialized(self) -> bool:
        """True once both a heading and a position have been measured."""
        return self._have_heading and self._have_position

    @property
    def z(self) -> float:
        """base_link's height in the field frame (m)."""
        return self.height.z

    @property
    def var_z(self) -> float:
        """Its variance (m^2), inf before the first height."""
        return self.height.var

    @property
    def rejected(self) -> int:
        return self.counters.rejected

    @property
    def resets(self) -> int:
        return self.counters.resets

    # --- state access ---
    @property
    def x(self) -> F64:
        """The state (a copy)."""
        return self._x.copy()

    @property
    def P(self) -> F64:
        """Its covariance (a copy)."""
        return self._p.copy()

    @P.setter
    def P(self, p: F64) -> None:
        self._p = np.array(p, dtype=float).reshape(5, 5)

    def position_sigma(self) -> float:
        p = self._p
        _, hi = eigenvalues_2x2(float(p[0, 0]), float(p[1, 1]), float(p[0, 1]))
        return math.sqrt(max(hi, 0.0))

    def localized(self) -> bool:
        return self.initialized and self.position_sigma() <= self.cfg.localized_sigma_m

    # --- bookkeeping ---
    def _refuse(self, kind: str, reason: str) -> bool:
        return self.counters.refuse(kind, reason)

    def _reset(self, kind: str, reason: str) -> None:
        self.counters.reset(kind, reason)

    def _check(self) -> bool:
        """After every step: a state or covariance that is not finite, or beyond what
        the robot can be, resets the filter to not localized; False then."""
        cfg = self.cfg
        problem = state_problem(
            self._x, self._p, self.z, self.var_z, cfg.max_speed, cfg.max_turn_rate
        )
        if problem is None:
            return True
        self._clear()
        self._reset(problem[0], f"{problem[1]}: not localized until the next fix")
        return False

    def _admit(self, what: str, t: float, bad: str | None) -> bool:
        """Refuse (and count) a measurement that is invalid (``bad`` says why) or
        stamped far from the filter's time; else advance the filter to ``t``."""
        if bad is not None:
            return self._refuse("invalid", f"{what}: {bad}")
        why, move = self._stamps.check(t, self.t)
        if why is not None:
            return self._refuse("stamp", f"{what}: {why}")
        if move:
            self._reset("time", f"filter time moved from {self.t:.3f} s to {t:.3f} s")
            self.t = t  # no prediction across a gap of unknown length
        self._advance(t)
        return True

    # --- prediction ---
    def predict(self, t: float) -> None:
        """Advance to ``t`` (s) on the caller's own clock, which is trusted: a filter
        whose time is further ahead of it than ``max_stamp_skew_s`` (stamps from
        another clock put it there) is moved back to it, its state unchanged."""
        if not math.isfinite(t):
            return
        if self.t is not None and t < self.t - self.cfg.max_stamp_skew_s:
            self._reset("time", f"filter time moved back from {self.t:.3f} s to {t:.3f} s")
            self.t = t
            return
        self._advance(t)
        self._check()

    def _advance(self, t: float) -> None:
        if self.t is None or t <= self.t:
            self.t = t if self.t is None else self.t
            return
        dt = min(t - self.t, self.cfg.max_gap_s)
        self.t = t
        x, f = unicycle(self._x, dt)
        self._set_x(x)
        share = motion_share(self.cfg, float(x[3]), float(x[4]))
        # standing, the robot does not accelerate either until it is commanded to
        # (and the next odometry says so): without this the velocities' random walk
        # between two zero-velocity updates leaks into the heading
        accel = self.cfg.still_noise_share if self._still else 1.0
        self._p = f @ self._p @ f.T + process_noise(self.cfg, share, accel, dt)
        self.height.var += share * self.cfg.z_process_sd**2 * dt

    def _correlation_scale(self, kind: str, t: float) -> float:
        """How much to scale the variance of a GNSS measurement of ``kind`` stamped
        ``t``: 1 + 2 tau / interval for a robot that stands or creeps, fading to 1 at
        full speed, where the process noise already keeps the filter from averaging
        more than a few correlated fixes."""
        last, self._last_t[kind] = self._last_t.get(kind), t
        tau = self.cfg.gnss_correlation_s
        if last is None or tau <= 0:
            return 1.0
        x = self.x
        slow = 1.0 - motion_share(self.cfg, float(x[3]), float(x[4]))
        return 1.0 + slow * 2.0 * tau / min(max(t - last, 0.01), 1.0)

    def _lag(self, t: float) -> float:
        """How old a measurement stamped ``t`` is against the filter's time: GNSS
        arrives ~0.1 s late, 3 deg of heading during an in-place turn at 0.6 rad/s,
        enough for the gate to reject a good measurement if it were fused as new."""
        if self.t is None or not self.cfg.lag_compensation:
            return 0.0
        return min(max(0.0, self.t - t), self.cfg.max_gap_s)

    # --- updates ---
    def _update(
        self,
        t: float,
        kind: str,
        z: F64,
        hx: Callable[[F64], F64],
        jac: Callable[[F64], F64],
        r: F64,
        direct: Sequence[int],
        residual: Callable[[F64, F64], F64] = _subtract,
    ) -> bool:
        """Gate and fuse one measurement; ``direct`` are the states it observes
        directly, re-initialised from a consistent run of rejections."""
        h = jac(self._x)
        innov = residual(z, hx(self._x))
        # the gate asks whether one fix is plausible at the receiver's stated accuracy;
        # the correlation scaling only limits how much a run of such fixes may teach
        s = h @ self._p @ h.T + r
        try:
            d2 = float(innov @ np.linalg.solve(s, innov))
        except np.linalg.LinAlgError:
            d2 = math.nan
        if not math.isfinite(d2):
            return self._refuse("invalid", f"{kind}: innovation {innov} is not usable")
        if kind != "odometry":
            r = r * self._correlation_scale(kind, t)
        run = self._runs.setdefault(kind, ConsistentRun())
        gate = CHI2_999[len(z)]
        if self.cfg.gate and self.initialized and d2 > gate:
            limit = self.cfg.reset_after_still if self._still else self.cfg.reset_after
            if run.add(innov, s, gate, residual) < limit:
                return self._refuse("gate", f"{kind}: {d2:.3g} from the estimate (gate {gate})")
            idx = list(direct)
            p = self.P
            p[idx, idx] += float(innov @ innov) * 4.0
            self.P = p
            self._reset(
                "relocalized",
                f"{kind}: re-initialised from {run.n} measurements "
                f"that agreed with each other, {np.round(innov, 3).tolist()} away",
            )
        run.clear()
        self._fuse(innov, h, r)
        return self._check()

    def _fuse(self, innov: F64, h: F64, r: F64) -> None:
        """The Kalman update of the state by ``innov`` (z - h(x)) through the Jacobian
        ``h``, in Joseph form (the covariance stays symmetric and positive). Written
        out rather than filterpy's general ``update``: that was half the filter's
        time per measurement (scipy's checked inverse, copies of z, x and P), and the
        filter takes tens of measurements per second of robot time, hundreds in a
        simulation faster than real time."""
        p = self._p
        ph = p @ h.T
        k = np.linalg.solve(h @ ph + r, ph.T).T  # P H' S^-1, S symmetric
        ikh = np.eye(5) - k @ h
        self._p = ikh @ p @ ikh.T + k @ r @ k.T
        self._set_x(self._x + k @ innov)

    def _set_x(self, x: F64) -> None:
        x = np.array(x, dtype=float).ravel()
        x[2] = wrap_angle(float(x[2]))
        self._x = x

    def update_odometry(
        self, t: float, v: float, w: float, var_v: float, var_w: float, still: bool = False
    ) -> bool:
        """Wheel odometry body velocities (m/s, rad/s; the encoders' view, blind to
        slip) with their variances (zero allowed: floored); with ``still`` a
        zero-velocity update instead (the caller knows the robot stands)."""
        bad = check_odometry(v, w, var_v, var_w, self.cfg.max_speed, self.cfg.max_turn_rate)
        if not self._admit("odometry", t, bad):
            return False
        h = np.zeros((2, 5))
        h[0, 3] = h[1, 4] = 1.0
        still = still and self.cfg.zero_velocity_updates
        self._still = still
        if still:
            z, r = np.zeros(2), np.eye(2) * self.cfg.zero_velocity_sd**2
        else:
            z, r = np.array([v, w]), np.diag([max(var_v, 1e-6), max(var_w, 1e-6)])
        return self._update(t, "odometry", z, lambda x: h @ x, lambda x: h, r, (3, 4))

    def update_antenna(
        self,
        t: float,
        xy: npt.ArrayLike,
        cov: npt.ArrayLike,
        lever: tuple[float, float],
        name: str = "",
    ) -> bool:
        """One antenna's horizontal position in the field frame (m) with its 2x2
        covariance (m^2); ``lever`` is its (x, y) offset in base_link. ``name`` tells
        the antennas apart (default: by lever): the correlation of its fixes over
        time and a run of its rejections are counted per antenna, so a lever that
        changes with the robot's tilt must not make each fix a stranger."""
        kind = f"antenna {name or lever}"
        p_xy, r, bad = check_antenna(xy, cov, self.cfg.min_fix_sd_m)
        if not self._admit(kind, t, bad):
            return False
        if not self._have_position or self._blind:
            # before a heading, each fix sets the position again (the lever arm's
            # direction is a guess: fusing through it fitted a restart facing
            # backwards a metre off, and the gate then refused every later fix)
            self._initialize_position(p_xy, lever)
            return self._check()
        hx, jac = antenna_model(lever, self._lag(t))
        return self._update(t, kind, p_xy, hx, jac, r, (0, 1))

    def update_heading(self, t: float, yaw: float, sd: float) -> bool:
        """The GNSS-compass heading (rad, field frame) with its 1-sigma (rad)."""
        var, bad = check_heading(yaw, sd, self.cfg.min_yaw_sd)
        if not self._admit("heading", t, bad):
            return False
        h = np.zeros((1, 5))
        h[0, 2] = 1.0
        h[0, 4] = -self._lag(t)  # the heading ``lag`` seconds ago
        if not self._have_heading:
            x, p = self.x, self.P
            x[2] = yaw + x[4] * self._lag(t)  # carried forward to the filter's time
            p[2, :] = p[:, 2] = 0.0
            p[2, 2] = var
            self._set_x(x)
            self.P = p
            self._have_heading = True
            return self._check()
        return self._update(
            t,
            "heading",
            np.array([yaw]),
            lambda x: h @ x,
            lambda x: h,
            np.array([[var]]),
            (2,),
            _angle_residual,
        )

    def update_height(self, t: float, z: float, var: float) -> bool:
        """base_link height from one antenna's RTK height (already less the
        antenna's height above base_link) with its variance (m^2)."""
        var, bad = check_height(z, var, self.cfg.min_fix_sd_m)
        if not self._admit("height", t, bad):
            return False
        scaled = var * self._correlation_scale("height", t)
        gate = CHI2_999[1] if self.cfg.gate else None
        done = self.height.update(z, var, scaled, gate, self.cfg.reset_after)
        if done == "gate":
            return self._refuse("gate", f"height: {z:.3f} m against {self.z:.3f} m")
        if done == "relocalized":
            self._reset("relocalized", f"height: re-initialised to {z:.3f} m")
        return self._check()

    def _initialize_position(self, xy: F64, lever: tuple[float, float]) -> None:
        x, p = self.x, self.P
        c, s = math.cos(x[2]), math.sin(x[2])
        lx, ly = lever
        x[0] = xy[0] - (c * lx - s * ly)
        x[1] = xy[1] - (s * lx + c * ly)
        p[0:2, :] = 0.0
        p[:, 0:2] = 0.0
        # without a heading yet the lever arm's direction is unknown: up to its length
        p[0, 0] = p[1, 1] = 0.05**2 + (0.0 if self._have_heading else lx * lx + ly * ly)
        self._set_x(x)
        self.P = p
        self._have_position = True
        self._blind = not self._have_heading
