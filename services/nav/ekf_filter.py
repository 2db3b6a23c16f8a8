"""The localization filter's core: its state and covariance, the prediction, the
gate and the Kalman update, and the bookkeeping of what it refused and reset. The
sensors' measurement models and their updates are :class:`services.nav.ekf.Localizer`'s.
Pure: times in seconds, no I/O."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from common.arrays import F64
from common.geo import wrap_angle
from services.nav.ekf_config import EkfConfig
from services.nav.ekf_guard import (
    ConsistentRun,
    Counters,
    StampGuard,
    eigenvalues_2x2,
    state_problem,
)
from services.nav.ekf_models import (
    HeightFilter,
    motion_share,
    process_noise,
    unicycle,
)

# chi-square 99.9 % quantiles for 1, 2, 3 degrees of freedom
CHI2_999 = {1: 10.83, 2: 13.82, 3: 16.27}


def angle_residual(a: F64, b: F64) -> F64:
    y = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    y[0] = wrap_angle(float(y[0]))
    return y


def subtract(a: F64, b: F64) -> F64:
    return np.asarray(a, dtype=float) - np.asarray(b, dtype=float)


class Filter:
    """The filter's state and its generic steps; ``counters`` says what it refused and
    reset (for health)."""

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
        # the turn's sideways slip: only what turns faster than the encoders' noise
        turned = max(0.0, abs(float(x[4])) - self.cfg.still_speed) * dt
        q = process_noise(self.cfg, share, accel, dt, turned)
        self._p = f @ self._p @ f.T + q
        self.height.var += share * self.cfg.z_process_sd**2 * dt

    def _correlation_scale(self, kind: str, t: float, position: bool) -> float:
        """How much to scale the variance of a GNSS measurement of ``kind`` stamped
        ``t``: 1 + 2 tau / interval. For a measurement of the ``position`` it fades to
        1 toward full speed, where the position's process noise already keeps the
        filter from averaging more than a few correlated fixes; the heading's process
        noise is the gyro's, small, so the filter averages tens of compass fixes while
        driving too, and the scaling holds at any speed."""
        last, self._last_t[kind] = self._last_t.get(kind), t
        tau = self.cfg.gnss_correlation_s
        if last is None or tau <= 0:
            return 1.0
        x = self.x
        slow = 1.0 - motion_share(self.cfg, float(x[3]), float(x[4])) if position else 1.0
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
        residual: Callable[[F64, F64], F64] = subtract,
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
            r = r * self._correlation_scale(kind, t, position=bool({0, 1} & set(direct)))
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
