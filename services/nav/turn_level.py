"""The IMU's tilt bias from turns in place, with no scan and no extra motion.

Standing on one spot, the robot's roll and pitch come from the ground's slope under
it, seen from its heading; the IMU adds its own bias, which does not turn with the
robot. On a slope rising ``(gx, gy)`` (field frame, m/m) a robot heading ``psi``
rolls by ``-gx sin psi + gy cos psi`` (left side up is positive roll, REP-103) and
pitches by ``-(gx cos psi + gy sin psi)`` (nose up is negative pitch). Samples taken
in headings at least ``min_span_deg`` apart, the standing before an in-place turn, the
turn itself, the standing after it, separate the four unknowns: the slope and the
two biases, by least squares. This is the classical reversal of a level, done at every
corner a route turns at and every scan location the robot leaves.

The ground is taken as a plane across the wheels' circle (0.75 m across on the
Husky): bumps longer than that (the field's are metres) tilt the robot alike in
every heading. A spot whose fit leaves residuals above ``max_residual_deg`` (a stone
under one wheel, a robot pushed while it turned) teaches nothing.
"""

from __future__ import annotations

import math
from typing import Annotated

import msgspec
import numpy as np

from common.messages.core import Positive

# a spot holds at most this many samples (over half an hour standing at 10 Hz): the
# headings a turn adds come at its end, so a long stand must not crowd them out
MAX_SAMPLES = 20_000


class TurnLevelConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The IMU's bias from turns in place (``[services.nav.tilt.turns]``)."""

    enabled: bool = True
    """Estimate the IMU's bias from turns in place."""
    spot_radius_m: Positive = 0.1
    """How far the robot may move and still be on one spot (a turn in place wanders a
    few centimetres sideways)."""
    still_speed: Positive = 0.02
    """Faster than this (m/s) it is driving, not turning in place."""
    min_span_deg: Positive = 60.0
    """The headings a spot needs (90 deg amplifies the IMU's noise by 1.4 against a
    reversal)."""
    min_samples: Annotated[int, msgspec.Meta(ge=4)] = 20
    """A spot's fit needs this many samples."""
    max_residual_deg: Positive = 0.3
    """A spot's fit needs residuals below this RMS."""


def heading_span(psi: np.ndarray) -> float:
    """The smallest arc (rad) that holds every heading in ``psi``."""
    a = np.sort(np.mod(psi, 2 * math.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * math.pi]))
    return float(2 * math.pi - gaps.max())


def fit_bias(psi: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares ``(gx, gy, roll bias, pitch bias)`` from samples at headings
    ``psi`` (rad), and the RMS residual (rad)."""
    n = len(psi)
    s, c = np.sin(psi), np.cos(psi)
    a = np.zeros((2 * n, 4))
    a[:n, 0], a[:n, 1], a[:n, 2] = -s, c, 1.0
    a[n:, 0], a[n:, 1], a[n:, 3] = -c, -s, 1.0
    z = np.concatenate([roll, pitch])
    sol, *_ = np.linalg.lstsq(a, z, rcond=None)
    rms = float(np.sqrt(np.mean((a @ sol - z) ** 2)))
    return sol, rms


class TurnLevel:
    """Feed IMU samples with the robot's pose (:meth:`sample`); each spot the robot
    turned on in place and left gives one estimate of the bias, averaged in ``bias``."""

    def __init__(self, cfg: TurnLevelConfig) -> None:
        self.cfg = cfg
        self._anchor: tuple[float, float] | None = None
        self._samples: list[tuple[float, float, float]] = []  # (psi, roll, pitch)
        self._estimates: list[tuple[float, float]] = []
        self.refused = 0  # spots turned on whose fit was too poor to use

    @property
    def spots(self) -> int:
        return len(self._estimates)

    @property
    def bias(self) -> tuple[float, float] | None:
        """The mean (roll, pitch) bias (rad) over the spots so far; None before one."""
        if not self._estimates:
            return None
        b = np.mean(np.asarray(self._estimates), axis=0)
        return float(b[0]), float(b[1])

    def sample(self, x: float, y: float, yaw: float, v: float, roll: float, pitch: float) -> bool:
        """One IMU sample (base_link's roll and pitch, rad) at pose ``(x, y, yaw)`` and
        odometry speed ``v``. Returns whether it closed a spot with a new estimate."""
        if not self.cfg.enabled:
            return False
        moved = abs(v) > self.cfg.still_speed or (
            self._anchor is not None
            and math.hypot(x - self._anchor[0], y - self._anchor[1]) > self.cfg.spot_radius_m
        )
        closed = self.close() if moved else False
        if abs(v) <= self.cfg.still_speed and len(self._samples) < MAX_SAMPLES:
            if self._anchor is None:
                self._anchor = (x, y)
            self._samples.append((yaw, roll, pitch))
        return closed

    def close(self) -> bool:
        """End the current spot; returns whether it gave an estimate."""
        samples, self._samples, self._anchor = self._samples, [], None
        if len(samples) < self.cfg.min_samples:
            return False
        psi, roll, pitch = (np.array(col) for col in zip(*samples, strict=True))
        if heading_span(psi) < math.radians(self.cfg.min_span_deg):
            return False
        sol, rms = fit_bias(psi, roll, pitch)
        if rms > math.radians(self.cfg.max_residual_deg):
            self.refused += 1
            return False
        self._estimates.append((float(sol[2]), float(sol[3])))
        return True
