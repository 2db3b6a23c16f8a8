"""Localization: an extended Kalman filter in the ``field`` frame (filterpy), fusing
wheel odometry, both GNSS antenna positions (through their lever arms) and the
GNSS-compass heading, as robot_localization does for the paper's robot.

State ``[x, y, yaw, v, w]`` (metres, radians, m/s, rad/s) of base_link; a unicycle
with constant velocities between measurements. Every measurement is gated by its
Mahalanobis distance, so a multipath jump is rejected rather than followed. Pure:
times in seconds, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated

import msgspec
import numpy as np
import numpy.typing as npt
from filterpy.kalman import ExtendedKalmanFilter

from common.geo import wrap_angle

F64 = npt.NDArray[np.float64]
Pos = Annotated[float, msgspec.Meta(gt=0)]

# chi-square 99.9 % quantiles for 1, 2, 3 degrees of freedom
CHI2_999 = {1: 10.83, 2: 13.82, 3: 16.27}


class EkfConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Process noise is a random walk on the velocities (accelerations, per s);
    ``gate_chi2_quantile`` selects the gate; ``localized_sigma_m`` is the largest
    1-sigma position uncertainty at which the robot still counts as localized."""

    accel_sd: Pos = 0.5  # m/s^2, Husky's commanded accelerations
    yaw_accel_sd: Pos = 1.0  # rad/s^2
    pos_process_sd: Pos = 0.005  # m/sqrt(s): unmodelled slip and terrain
    yaw_process_sd: Pos = 0.005  # rad/sqrt(s)
    gate: bool = True
    localized_sigma_m: Pos = 0.05
    # after this many consecutive rejections of one measurement type the filter, not
    # the sensor, is taken to be wrong: its covariance is inflated and the measurement
    # accepted (a heading that drifted during an unaided turn would otherwise lock
    # every later fix out)
    reset_after: Annotated[int, msgspec.Meta(ge=1)] = 10
    # standing still after zero-velocity updates the filter is rarely wrong, while the
    # GNSS error is correlated over seconds: a 1 s run of rejections there is a
    # multipath excursion to sit out, not a reason to jump to it
    reset_after_still: Annotated[int, msgspec.Meta(ge=1)] = 100
    # GNSS errors are correlated over seconds (multipath): fixes taken while the robot
    # stands or creeps repeat the same error, so there each one is fused with its
    # variance scaled by 1 + 2 tau / interval, the variance of a mean of such samples
    # (fading out toward full speed). Without it the covariance of a standing robot
    # shrinks as if every fix were independent and claims millimetres it does not
    # have, and a creep of a few millimetres lets the fixes of that moment pull the
    # settled estimate. 0 turns the correction off.
    gnss_correlation_s: Annotated[float, msgspec.Meta(ge=0)] = 2.0
    # base_link height: a random walk (m/sqrt(s), at full speed; the terrain's
    # bumps and slope) observed by the antennas' RTK heights
    z_process_sd: Pos = 0.05
    max_gap_s: Pos = 1.0  # predict at most this far in one step
    # robot_localization's dynamic_process_noise_covariance: the position and heading
    # process noise stand for slip, which needs motion, so it scales with the speed
    # (full at ``full_noise_speed`` m/s or rad/s, never below ``still_noise_share``
    # of it). A robot standing still then averages GNSS over the whole scan instead
    # of following every fix's multipath wander. Speeds below the encoders' noise
    # (``still_speed``, m/s and rad/s) count as standing.
    dynamic_process_noise: bool = True
    full_noise_speed: Pos = 0.2
    still_speed: Pos = 0.01
    still_noise_share: Annotated[float, msgspec.Meta(gt=0, le=1)] = 1e-5
    # zero-velocity update: while the robot is known to stand (wheels commanded still
    # and reading still), its velocities are measured as zero to this 1-sigma (m/s,
    # rad/s) instead of integrating the encoders' noise into position and heading
    zero_velocity_sd: Pos = 1e-4


def _angle_residual(a: F64, b: F64) -> F64:
    y = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    y[0] = wrap_angle(float(y[0]))
    return y


class Localizer:
    def __init__(self, cfg: EkfConfig) -> None:
        self.cfg = cfg
        self.kf = ExtendedKalmanFilter(dim_x=5, dim_z=2)
        self.kf.x = np.zeros((5, 1))  # filterpy keeps the state as a column
        self.kf.P = np.diag([1e4, 1e4, math.pi**2, 1.0, 1.0])
        self.t: float | None = None
        self.rejected = 0
        self.resets = 0
        self._run: dict[str, int] = {}
        self._have_heading = False
        self._have_position = False
        self._still = False  # the last odometry was a zero-velocity update
        self._last_t: dict[str, float] = {}  # stamp of each kind's last measurement
        # base_link height in the field frame, a scalar filter beside the planar one
        # (the antennas' heights say nothing about x, y or yaw on a level robot)
        self.z = 0.0
        self.var_z = math.inf

    @property
    def initialized(self) -> bool:
        """True once both a heading and a position have been measured."""
        return self._have_heading and self._have_position

    # --- state access ---
    @property
    def x(self) -> F64:
        return np.asarray(self.kf.x, dtype=float).ravel()

    @property
    def P(self) -> F64:
        return np.asarray(self.kf.P, dtype=float)

    def position_sigma(self) -> float:
        return float(math.sqrt(max(np.linalg.eigvalsh(self.P[:2, :2]).max(), 0.0)))

    def localized(self) -> bool:
        return self.initialized and self.position_sigma() <= self.cfg.localized_sigma_m

    # --- prediction ---
    def predict(self, t: float) -> None:
        if self.t is None or t <= self.t:
            self.t = t if self.t is None else self.t
            return
        dt = min(t - self.t, self.cfg.max_gap_s)
        self.t = t
        x, y, yaw, v, w = self.x
        c, s = math.cos(yaw + 0.5 * w * dt), math.sin(yaw + 0.5 * w * dt)
        self._set_x(np.array([x + v * dt * c, y + v * dt * s, yaw + w * dt, v, w]))
        f = np.eye(5)
        f[0, 2], f[0, 3], f[0, 4] = -v * dt * s, dt * c, -0.5 * v * dt * dt * s
        f[1, 2], f[1, 3], f[1, 4] = v * dt * c, dt * s, 0.5 * v * dt * dt * c
        f[2, 4] = dt
        cfg = self.cfg
        share = self.motion_share(v, w)
        # standing, the robot does not accelerate either until it is commanded to
        # (and the next odometry says so): without this the velocities' random walk
        # between two zero-velocity updates leaks into the heading
        accel_share = cfg.still_noise_share if self._still else 1.0
        q = np.diag(
            [
                share * cfg.pos_process_sd**2 * dt,
                share * cfg.pos_process_sd**2 * dt,
                share * cfg.yaw_process_sd**2 * dt,
                accel_share * cfg.accel_sd**2 * dt,
                accel_share * cfg.yaw_accel_sd**2 * dt,
            ]
        )
        self.kf.P = f @ self.P @ f.T + q
        self.var_z += share * cfg.z_process_sd**2 * dt

    def motion_share(self, v: float, w: float) -> float:
        """The share of the full position and heading process noise at body speeds
        ``v`` (m/s) and ``w`` (rad/s); 1 without dynamic process noise."""
        cfg = self.cfg
        if not cfg.dynamic_process_noise:
            return 1.0
        moving = max(0.0, abs(v) - cfg.still_speed) + max(0.0, abs(w) - cfg.still_speed)
        return min(1.0, max(cfg.still_noise_share, moving / cfg.full_noise_speed))

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
        slow = 1.0 - self.motion_share(float(x[3]), float(x[4]))
        return 1.0 + slow * 2.0 * tau / min(max(t - last, 0.01), 1.0)

    def _lag(self, t: float) -> float:
        """How old a measurement stamped ``t`` is against the filter's time: GNSS
        arrives ~0.1 s late, 3 deg of heading during an in-place turn at 0.6 rad/s,
        enough for the gate to reject a good measurement if it were fused as new."""
        return 0.0 if self.t is None else min(max(0.0, self.t - t), self.cfg.max_gap_s)

    # --- updates ---
    def _update(
        self,
        t: float,
        kind: str,
        z: F64,
        hx: Callable[[F64], F64],
        jac: Callable[[F64], F64],
        r: F64,
        residual: Callable[[F64, F64], F64] = np.subtract,
    ) -> bool:
        x = self.x.reshape(-1, 1)
        h = jac(x.ravel())
        innov = residual(z, hx(x.ravel()))
        # the gate asks whether one fix is plausible at the receiver's stated accuracy;
        # the correlation scaling only limits how much a run of such fixes may teach
        s = h @ self.P @ h.T + r
        d2 = float(innov @ np.linalg.solve(s, innov))
        if kind != "odometry":
            r = r * self._correlation_scale(kind, t)
        if self.cfg.gate and self.initialized and d2 > CHI2_999[len(z)]:
            self.rejected += 1
            self._run[kind] = self._run.get(kind, 0) + 1
            limit = self.cfg.reset_after_still if self._still else self.cfg.reset_after
            if self._run[kind] < limit:
                return False
            observed = np.flatnonzero(np.abs(h).sum(axis=0) > 0)
            p = self.P
            p[observed, observed] += float(innov @ innov) * 4.0
            self.kf.P = p
            self.resets += 1
        self._run[kind] = 0
        self.kf.dim_z = len(z)
        self.kf.update(
            z.reshape(-1, 1),
            lambda xx: jac(np.asarray(xx).ravel()),
            lambda xx: hx(np.asarray(xx).ravel()).reshape(-1, 1),
            R=r,
            residual=lambda a, b: residual(np.asarray(a).ravel(), np.asarray(b).ravel()).reshape(
                -1, 1
            ),
        )
        self._set_x(self.x)
        return True

    def _set_x(self, x: F64) -> None:
        x = np.array(x, dtype=float).ravel()
        x[2] = wrap_angle(float(x[2]))
        self.kf.x = x.reshape(-1, 1)

    def update_odometry(
        self, t: float, v: float, w: float, var_v: float, var_w: float, still: bool = False
    ) -> bool:
        """Wheel odometry body velocities (the encoders' view, blind to slip); with
        ``still`` a zero-velocity update instead (the caller knows the robot stands)."""
        self.predict(t)
        h = np.zeros((2, 5))
        h[0, 3] = h[1, 4] = 1.0
        self._still = still
        if still:
            z, r = np.zeros(2), np.eye(2) * self.cfg.zero_velocity_sd**2
        else:
            z, r = np.array([v, w]), np.diag([max(var_v, 1e-6), max(var_w, 1e-6)])
        return self._update(t, "odometry", z, lambda x: h @ x, lambda x: h, r)

    def update_antenna(self, t: float, xy: F64, cov: F64, lever: tuple[float, float]) -> bool:
        """One antenna's horizontal position in the field frame; ``lever`` is its
        (x, y) offset in base_link."""
        self.predict(t)
        lag = self._lag(t)
        lx, ly = lever
        if not self._have_position:
            self._initialize_position(xy, lever)
            return True

        def hx(x: F64) -> F64:
            # where the antenna was ``lag`` seconds ago (constant velocities)
            yaw = x[2] - x[4] * lag
            c, s = math.cos(yaw), math.sin(yaw)
            bx = x[0] - x[3] * lag * math.cos(x[2])
            by = x[1] - x[3] * lag * math.sin(x[2])
            return np.array([bx + c * lx - s * ly, by + s * lx + c * ly])

        def jac(x: F64) -> F64:
            yaw = x[2] - x[4] * lag
            c, s = math.cos(yaw), math.sin(yaw)
            dx, dy = -s * lx - c * ly, c * lx - s * ly
            h = np.zeros((2, 5))
            h[0, 0] = h[1, 1] = 1.0
            h[0, 2] = dx + x[3] * lag * math.sin(x[2])
            h[1, 2] = dy - x[3] * lag * math.cos(x[2])
            h[0, 3], h[1, 3] = -lag * math.cos(x[2]), -lag * math.sin(x[2])
            h[0, 4], h[1, 4] = -lag * dx, -lag * dy
            return h

        return self._update(
            t,
            f"antenna {lever}",
            np.asarray(xy, dtype=float),
            hx,
            jac,
            np.asarray(cov, dtype=float),
        )

    def update_heading(self, t: float, yaw: float, sd: float) -> bool:
        self.predict(t)
        h = np.zeros((1, 5))
        h[0, 2] = 1.0
        h[0, 4] = -self._lag(t)  # the heading ``lag`` seconds ago
        if not self._have_heading:
            x, p = self.x, self.P
            x[2] = yaw + x[4] * self._lag(t)  # carried forward to the filter's time
            p[2, :] = p[:, 2] = 0.0
            p[2, 2] = sd * sd
            self._set_x(x)
            self.kf.P = p
            self._have_heading = True
            return True
        return self._update(
            t,
            "heading",
            np.array([yaw]),
            lambda x: h @ x,
            lambda x: h,
            np.array([[sd * sd]]),
            _angle_residual,
        )

    def update_height(self, t: float, z: float, var: float) -> bool:
        """base_link height from one antenna's RTK height (already less the
        antenna's height above base_link) with its variance (m^2)."""
        self.predict(t)
        var = max(var, 1e-8)
        scaled = var * self._correlation_scale("height", t)
        if not math.isfinite(self.var_z):
            self.z, self.var_z = z, var
            return True
        if self.cfg.gate and (z - self.z) ** 2 / (self.var_z + var) > CHI2_999[1]:
            self.rejected += 1
            return False
        k = self.var_z / (self.var_z + scaled)
        self.z += k * (z - self.z)
        self.var_z *= 1.0 - k
        return True

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
        self.kf.P = p
        self._have_position = True
