"""The IMU's gyroscope as a measurement of the yaw rate.

Wheel odometry is blind to how a skid-steer robot turns: its wheels scrub sideways,
so the body yaws at 80-95 % of the rate the wheel speeds imply, less on loose ground,
and the share wanders. Through a 90 deg turn in place that is several degrees the
filter believes the robot turned and it did not; the GNSS compass (a degree or two
per fix under a crop) pulls the heading back only over the seconds that follow, and
the robot drives off the corner at the heading error of that moment, opening a
cross-track error that pure pursuit then takes metres to close.

A MEMS gyro measures the body's rate directly, at the price of a bias of a few
mrad/s that changes from one power-on to the next. Every time the robot stands (the
filter's zero-velocity updates say so) the gyro's reading *is* that bias, so it is
averaged there (``bias_tau_s``). Until then, and as far as the standing has not
pinned it, the bias is an uncertainty on top of each sample's noise
(``unknown_bias_sd``): in a turn, where the wheels' rate is off by 5-20 % of it, the
gyro still wins, so a robot that drives off at once (or a navigation restarted while
driving) turns by its gyro from the first corner; on a straight line, where a bias
would turn the heading slowly against the compass, the wheels do.

While the gyro's rate is fresh it stands in for the wheels' in each odometry
update (robot_localization users do the same: the odometry's ``vyaw`` off, the
IMU's on). It is not fused as a measurement of its own: the filter's yaw rate is a
random walk of a rad/s^2, so between two gyro samples (10 Hz) it would follow the
odometry (50 Hz) again, or, with the wheels' rate ignored, whatever slow fixes of a
creeping robot suggest. A sample used for several odometry updates has its variance
multiplied by their number, so it weighs what one sample does; the wheels' rate
and the gyro's are weighted by their variances.
"""

from __future__ import annotations

import math

import msgspec

from common.messages.core import Positive


class GyroConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The IMU's yaw rate beside the wheels' (docs/navigation.md)."""

    enabled: bool = True
    """Fuse the IMU's yaw rate (false: the paper's odometry-and-compass filter)."""
    sd: Positive = 0.01
    """The 1-sigma of one sample (rad/s; UM7-class rate gyros read about 0.01 rad/s of
    white noise at 10-20 Hz)."""
    bias_tau_s: Positive = 30.0
    """The standing average's time constant (s): long against the noise, short against
    the bias's drift with the unit's temperature over a field day."""
    unknown_bias_sd: Positive = 0.005
    """The bias's 1-sigma before the robot has stood (rad/s; a few mrad/s from one
    power-on to the next for UM7-class MEMS gyros); each standing sample narrows it, as
    a mean of samples of ``sd`` (at most ``bias_tau_s`` worth)."""
    max_rate: Positive = 4.0
    """A reading beyond it (rad/s) is refused as absurd (the Husky turns at 2 rad/s at
    most)."""
    max_age_s: Positive = 0.3
    """A rate older than this (s) no longer stands in for the wheels'."""


class Gyro:
    """The yaw rate, less the bias learnt while standing; pure (times in seconds)."""

    def __init__(self, cfg: GyroConfig) -> None:
        self.cfg = cfg
        self.bias = 0.0
        self.still_samples = 0
        self.refused = 0
        self._t: float | None = None
        self._rate: tuple[float, float] | None = None  # (time, rate) of the last sample
        self._interval = 0.1  # between two samples (s), as they come

    @property
    def bias_var(self) -> float:
        """The variance of the bias taken off each rate ((rad/s)²): the prior narrowed by
        the standing samples averaged into it."""
        n = min(float(self.still_samples), self.cfg.bias_tau_s / self._interval)
        return 1.0 / (1.0 / self.cfg.unknown_bias_sd**2 + n / self.cfg.sd**2)

    def sample(self, t: float, wz: float, still: bool) -> None:
        """One reading ``wz`` (rad/s) at ``t``: learnt from while ``still``, else kept
        (bias taken off) for :meth:`odometry_rate`; an absurd one is counted."""
        if not self.cfg.enabled:
            return
        if not (math.isfinite(wz) and math.isfinite(t)) or abs(wz) > self.cfg.max_rate:
            self.refused += 1
            return
        if self._t is not None and t > self._t:
            self._interval = min(t - self._t, self.cfg.max_age_s)
        dt = 0.0 if self._t is None else max(0.0, t - self._t)
        self._t = t
        if still:
            # a running mean for the first samples, then an exponential one
            n = self.still_samples = self.still_samples + 1
            k = max(1.0 / n, 1.0 - math.exp(-dt / self.cfg.bias_tau_s))
            self.bias += k * (wz - self.bias)
            self._rate = None
        else:
            self._rate = (t, wz - self.bias)

    def odometry_rate(
        self, t: float, w: float, var_w: float, interval: float
    ) -> tuple[float, float]:
        """The yaw rate and its variance for an odometry update at ``t`` (s) whose
        wheels say ``w`` (rad/s) with ``var_w``, ``interval`` seconds after the one
        before: while the gyro's last rate is fresh, the two weighted by their
        variances (the gyro's wins in a turn, where the wheels scrub; the wheels' at a
        creep, below the gyro's noise), else the wheels' alone. The gyro's variance is
        its noise's (a sample used for several updates weighs as one) and its bias's,
        which is the same in every update and so is not divided among them."""
        if self._rate is None or not 0.0 <= t - self._rate[0] <= self.cfg.max_age_s:
            return w, var_w
        var_g = self.cfg.sd**2 * max(1.0, self._interval / max(interval, 1e-3)) + self.bias_var
        var_w = max(var_w, 1e-12)
        var = 1.0 / (1.0 / var_w + 1.0 / var_g)
        return var * (w / var_w + self._rate[1] / var_g), var
