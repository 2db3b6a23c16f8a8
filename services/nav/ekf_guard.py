"""What the localization filter refuses before it fuses, and how it tells a wrong
filter from a wrong sensor. Pure functions and a small tracker; no filter state.

Messages are finite by schema, but a well-formed value can still be absurd: a fix
1000 km away, a covariance of 1e-30 m^2 or of zero, one that is not a covariance at
all (not positive semi-definite). Each of these once drove the filter to NaN for
good. They are refused here with a one-line reason, before any arithmetic.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from common.arrays import F64

log = logging.getLogger("services.nav.ekf")

#: the largest coordinate (m) in the field frame: the bus's own bound
#: (common.messages.core.Coordinate), so squares of differences stay finite
MAX_COORD_M = 1e7
#: the largest height (m) anything on the ground has
MAX_HEIGHT_M = 1e5
#: a heading more than two turns from zero is garbage, wrapped or not
MAX_YAW = 4.0 * math.pi


def not_finite(**values: float) -> str | None:
    """The first of ``values`` that is not a finite number, as a reason; else None."""
    for name, v in values.items():
        if not math.isfinite(v):
            return f"{name} {v!r} is not finite"
    return None


def out_of(limit: float, **values: float) -> str | None:
    """The first of ``values`` not finite or beyond +-``limit``, as a reason; else None."""
    bad = not_finite(**values)
    if bad is not None:
        return bad
    for name, v in values.items():
        if abs(v) > limit:
            return f"{name} {v:.6g} is beyond +-{limit:g}"
    return None


def variance(var: float, floor: float, name: str = "variance") -> tuple[float, str | None]:
    """A measurement variance as fused: finite and > 0 (zero claims a perfect sensor:
    it is what an unfilled covariance looks like), raised to ``floor``."""
    if not math.isfinite(var) or var <= 0.0:
        return 0.0, f"{name} {var!r} is not a positive finite number"
    return max(var, floor), None


def covariance(cov: npt.ArrayLike, n: int, floor: float) -> tuple[F64, str | None]:
    """A measurement covariance (n x n) as fused: finite, symmetric, positive
    semi-definite and not zero, its eigenvalues raised to ``floor`` (a variance).
    The reason it cannot be used otherwise."""
    c = np.asarray(cov, dtype=float)
    if c.shape != (n, n):
        return c, f"covariance of shape {c.shape}, not ({n}, {n})"
    if not np.isfinite(c).all():
        return c, "covariance is not finite"
    scale = float(np.abs(c).max())
    if scale <= 0.0:
        return c, "covariance is zero"
    if float(np.abs(c - c.T).max()) > 1e-6 * scale:
        return c, "covariance is not symmetric"
    lo = min_eigenvalue(c)
    if lo < -1e-9 * scale:
        return c, f"covariance is not positive semi-definite (eigenvalue {lo:.3g})"
    if lo >= floor:
        return c, None  # the usual case, fused exactly as given
    w, v = np.linalg.eigh(0.5 * (c + c.T))
    return (v * np.maximum(w, floor)) @ v.T, None


def eigenvalues_2x2(a: float, d: float, b: float) -> tuple[float, float]:
    """(smaller, larger) eigenvalue of the symmetric matrix [[a, b], [b, d]], in
    closed form: every fix's covariance and every tick's position sigma ask it, and
    ``eigh`` was a third of the filter's time per fix."""
    mid, half = 0.5 * (a + d), math.hypot(0.5 * (a - d), b)
    return mid - half, mid + half


def min_eigenvalue(c: F64) -> float:
    """The smallest eigenvalue of a symmetric matrix (a 2 x 2 in closed form)."""
    if c.shape == (2, 2):
        return eigenvalues_2x2(float(c[0, 0]), float(c[1, 1]), 0.5 * float(c[0, 1] + c[1, 0]))[0]
    return float(np.linalg.eigvalsh(0.5 * (c + c.T)).min())


class ConsistentRun:
    """Counts consecutive rejected measurements of one kind that agree with each
    other: each innovation within the chi-square gate of the one before it, under
    the sum of their innovation covariances. A filter that is wrong sees the same
    innovation again and again; a sensor that is wrong (multipath spikes, garbage)
    does not, and restarts the count."""

    def __init__(self) -> None:
        self.n = 0
        self._last: tuple[F64, F64] | None = None

    def add(
        self,
        innov: F64,
        s: F64,
        chi2: float,
        residual: Callable[[F64, F64], F64],
    ) -> int:
        """Record one rejected measurement; the length of the run it belongs to."""
        agree = False
        if self._last is not None:
            last_innov, last_s = self._last
            d = residual(innov, last_innov)
            try:
                agree = float(d @ np.linalg.solve(s + last_s, d)) <= chi2
            except np.linalg.LinAlgError:
                agree = False
        self.n = self.n + 1 if agree else 1
        self._last = (np.array(innov, dtype=float), np.array(s, dtype=float))
        return self.n

    def clear(self) -> None:
        self.n = 0
        self._last = None


class Counters:
    """What the filter refused and reset, for the service's health: ``rejected``
    (measurements not fused) by kind in ``rejected_by``, ``resets`` (beliefs thrown
    away) by kind in ``resets_by``, and ``last_reason``, the latest as one line. Logs
    the 1st, 10th, 100th, ... of each kind, so a stream of bad input cannot flood
    the log and a persistent one still shows."""

    def __init__(self) -> None:
        self.rejected = 0
        self.rejected_by: dict[str, int] = {}
        self.resets = 0
        self.resets_by: dict[str, int] = {}
        self.last_reason = ""

    @staticmethod
    def _say(kind: str, text: str, n: int) -> None:
        if n == 10 ** int(math.log10(n)):
            log.warning("localization: %s (%s: %d so far)", text, kind, n)

    def refuse(self, kind: str, reason: str) -> bool:
        """Count a measurement refused as ``kind``; always False (what to return)."""
        self.rejected += 1
        n = self.rejected_by[kind] = self.rejected_by.get(kind, 0) + 1
        self.last_reason = f"{kind}: {reason}"
        if kind != "gate":  # gating is the filter working; the rest is a bad peer
            self._say(kind, f"refused a measurement, {reason}", n)
        return False

    def reset(self, kind: str, reason: str) -> None:
        self.resets += 1
        n = self.resets_by[kind] = self.resets_by.get(kind, 0) + 1
        self.last_reason = f"{kind}: {reason}"
        self._say(kind, reason, n)


class StampGuard:
    """Refuses measurements stamped further than ``skew_s`` from the filter's time.
    Ahead of it, ``after`` in a row stamped alike (each within ``skew_s`` of the one
    before) mean the filter's time, not theirs, was wrong (it was not advanced for a
    while): it moves to them. Behind it they are stale, and stay refused: only the
    caller's own clock (:meth:`Localizer.predict`) moves the filter's time back."""

    def __init__(self, skew_s: float, after: int) -> None:
        self.skew_s, self.after = skew_s, after
        self._run = 0
        self._last = 0.0

    def check(self, t: float, filter_t: float | None) -> tuple[str | None, bool]:
        """(why ``t`` is refused or None, whether the filter's time must move to it)."""
        if not math.isfinite(t):
            return f"stamp {t!r} is not finite", False
        if filter_t is None or abs(t - filter_t) <= self.skew_s:
            self._run = 0
            return None, False
        why = f"stamp {t:.3f} s is {t - filter_t:+.3f} s from the filter's time"
        if t < filter_t:
            self._run = 0
            return why, False
        alike = self._run > 0 and abs(t - self._last) <= self.skew_s
        self._run, self._last = (self._run + 1 if alike else 1), t
        if self._run < self.after:
            return why, False
        self._run = 0
        return None, True


# --- what each measurement must be (reasons are one line, naming the value) ---
def check_odometry(
    v: float, w: float, var_v: float, var_w: float, max_speed: float, max_turn_rate: float
) -> str | None:
    """Body velocities within the command's bounds; variances finite and >= 0 (an
    encoder's variance may be unset, zero: the filter floors it)."""
    bad = out_of(max_speed, v=v) or out_of(max_turn_rate, w=w)
    bad = bad or not_finite(var_v=var_v, var_w=var_w)
    if bad is None and min(var_v, var_w) < 0:
        bad = f"variance {min(var_v, var_w)!r} is negative"
    return bad


def check_antenna(
    xy: npt.ArrayLike, cov: npt.ArrayLike, min_sd_m: float
) -> tuple[F64, F64, str | None]:
    """(position, covariance as fused, why not) for a 2-D antenna fix in metres."""
    p = np.asarray(xy, dtype=float).ravel()
    r, bad = covariance(cov, 2, min_sd_m**2)
    if p.shape != (2,):
        return p, r, f"position of shape {p.shape}, not (2,)"
    return p, r, out_of(MAX_COORD_M, x=float(p[0]), y=float(p[1])) or bad


def check_heading(yaw: float, sd: float, min_sd: float) -> tuple[float, str | None]:
    """(variance as fused, why not) for a heading in radians and its 1-sigma, which
    is raised to ``min_sd`` and capped at two turns (beyond that it says nothing)."""
    bad = None if math.isfinite(sd) and sd > 0 else f"yaw_sd {sd!r} is not positive"
    return min(max(sd, min_sd), MAX_YAW) ** 2, out_of(MAX_YAW, yaw=yaw) or bad


def check_height(z: float, var: float, min_sd_m: float) -> tuple[float, str | None]:
    """(variance as fused, why not) for a height in metres and its variance."""
    var, bad = variance(var, min_sd_m**2)
    return var, out_of(MAX_HEIGHT_M, z=z) or bad


def state_problem(
    x: F64, p: F64, z: float, var_z: float, max_speed: float, max_turn_rate: float
) -> tuple[str, str] | None:
    """(kind, reason) when the filter's own state cannot be right, else None:
    ``nonfinite`` (a NaN or infinity anywhere, a negative variance) or
    ``implausible`` (beyond the field frame's extent, or velocities past twice the
    command's bounds: what ungated updates of absurd fixes before initialisation can
    reach, and what no subscriber would decode)."""
    # one sum: a NaN or infinity anywhere makes it non-finite (a finite state that
    # overflowed it would be far beyond the plausible bounds below anyway)
    if not math.isfinite(float(x.sum()) + float(p.sum()) + z):
        return "nonfinite", "state or covariance not finite"
    if not var_z >= 0.0 or float(p.diagonal().min()) < 0.0:  # var_z: inf until the first height
        return "nonfinite", "negative variance"
    if (
        max(abs(x[0]), abs(x[1])) > MAX_COORD_M
        or abs(x[3]) > 2.0 * max_speed
        or abs(x[4]) > 2.0 * max_turn_rate
        or abs(z) > MAX_HEIGHT_M
    ):
        return "implausible", f"state {np.round(x, 3).tolist()} is beyond what the robot can be"
    return None
