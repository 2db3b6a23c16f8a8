"""base_link's roll and pitch from the IMU, and what they do to the antennas.

The antennas stand 1.1 m above base_link, so a robot tilted by a degree has them
about 2 cm off to the side of where a planar filter puts base_link: the robot then
stops that far from its scan location while its estimate says it is on it. With the
tilt known, an antenna's horizontal lever arm is that of its 3D lever arm turned by
roll and pitch (:meth:`Tilt.lever`), and the filter places base_link under the
antennas correctly.

The IMU's tilt is an accelerometer-levelled one: it takes the specific force for
gravity, so while the robot speeds up, brakes or turns it reads the motion as tilt.
Only samples taken while the odometry says the body hardly accelerates
(``max_accel``, over ``accel_window_s``) are fused, low-passed with ``tau_s``; the
ground changes over metres, so the last good tilt stands for the bad stretches.

A bias of the unit's (turn-on bias, mounting) tilts every correction the same way.
Two things measure it. Every turn in place on one spot does, a level's reversal
(:mod:`services.nav.turn_level`): the ground's slope turns with the robot, the bias
does not. Better, the scanner's dual-axis compensator measures the tilt at every scan
(FARO: 0.015 deg) within its working range: at the end of a scan taken while the
robot stood still, the difference between the IMU's tilt and the compensator's is
the IMU's bias, averaged over the scans so far and, once there is one, preferred to
the turns'.
"""

from __future__ import annotations

import math
from collections import deque

import msgspec
import numpy as np

from common.geo import euler_zyx, rot_zyx
from common.messages.core import Positive
from common.robot import ImuMount
from services.nav.turn_level import TurnLevel, TurnLevelConfig


class TiltConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The IMU's tilt on the antennas' lever arms (docs/navigation.md)."""

    enabled: bool = True
    """False leaves the antennas' lean uncorrected (the paper's planar localization)."""
    tau_s: Positive = 0.5
    """Low-pass time constant of the tilt (s)."""
    max_accel: Positive = 0.1
    """Fuse IMU samples only while the body's longitudinal and centripetal accelerations
    (from odometry over ``accel_window_s``) stay below this (m/s²): 0.1 m/s² leaks at
    most 0.3 deg into the UM7's tilt, 5 mm at the antennas."""
    accel_window_s: Positive = 0.5
    """The odometry window the accelerations are taken over (s)."""
    max_age_s: Positive = 2.0
    """An older tilt is not used (no IMU: the lean stays uncorrected)."""
    calibrate: bool = True
    """Take the IMU's bias off with the scanner's compensator, read where the compensator
    is valid."""
    compensator_range_deg: Positive = 2.0
    """Where the scanner's compensator is valid (FARO: ±2 deg)."""
    max_tilt_deg: Positive = 20.0
    """A sample beyond it is refused as absurd (a Husky tilted 20 deg is not surveying;
    the UM7 says so only when broken or lied for)."""
    turns: TurnLevelConfig = msgspec.field(default_factory=TurnLevelConfig)
    """The bias from turns in place, until a scan's compensator reading gives a better
    one."""


def tilt_of(r: np.ndarray) -> tuple[float, float]:
    """(roll, pitch) of a rotation matrix (its yaw does not enter them)."""
    roll, pitch, _ = euler_zyx(r)
    return roll, pitch


class Tilt:
    """The tilt filter: odometry (``motion``), IMU samples (``imu``), compensator
    readings (``compensator``) in; base_link's (roll, pitch) and tilted levers out."""

    def __init__(self, cfg: TiltConfig, mount: ImuMount) -> None:
        self.cfg = cfg
        self._mount_t = rot_zyx(mount.roll_rad, mount.pitch_rad, mount.yaw_rad).T
        self._odom: deque[tuple[float, float]] = deque()  # (t, v)
        self._w = 0.0
        self.raw: tuple[float, float] | None = None  # low-passed IMU tilt of base_link
        self._t = -math.inf  # time of the last fused sample
        self._compensated = (0.0, 0.0)  # the bias by the compensator, mean over scans
        self.calibrations = 0  # scans that calibrated it
        self.turns = TurnLevel(cfg.turns)
        self.rejected = 0  # samples refused as taken under acceleration

    @property
    def bias(self) -> tuple[float, float]:
        """The IMU's (roll, pitch) bias (rad) taken off its readings: the
        compensator's, else the turns', else none known."""
        if self.calibrations:
            return self._compensated
        return self.turns.bias or (0.0, 0.0)

    def motion(self, t: float, v: float, w: float) -> None:
        """One odometry reading (s, m/s, rad/s)."""
        q = self._odom
        q.append((t, v))
        while q and q[0][0] < t - self.cfg.accel_window_s:
            q.popleft()
        self._w = w

    def quiet(self) -> bool:
        """Whether the body is hardly accelerating now, by the odometry."""
        q = self._odom
        if len(q) < 2:
            return True
        (t0, v0), (t1, v1) = q[0], q[-1]
        a_long = abs(v1 - v0) / max(t1 - t0, 1e-3)
        return a_long <= self.cfg.max_accel and abs(v1 * self._w) <= self.cfg.max_accel

    def imu(
        self,
        t: float,
        roll: float,
        pitch: float,
        pose: tuple[float, float, float] | None = None,
    ) -> bool:
        """One IMU sample at ``t`` (s, on the caller's clock, never earlier than the
        last): the unit's own roll and pitch (rad), and the robot's estimated ``pose``
        (x, y, yaw in the field frame; for the turns' calibration). Returns whether it
        was fused."""
        lim = math.radians(self.cfg.max_tilt_deg)
        if not (abs(roll) <= lim and abs(pitch) <= lim) or t < self._t or not self.quiet():
            self.rejected += 1
            return False
        # base_link's tilt: the unit's attitude turned back by its mounting
        b = tilt_of(rot_zyx(roll, pitch, 0.0) @ self._mount_t)
        if pose is not None and self._odom:
            self.turns.sample(*pose, self._odom[-1][1], *b)
        if self.raw is None or t - self._t > self.cfg.max_age_s:
            self.raw = b
        else:
            k = 1.0 - math.exp(-max(t - self._t, 0.0) / self.cfg.tau_s)
            r, p = self.raw
            self.raw = (r + k * (b[0] - r), p + k * (b[1] - p))
        self._t = max(self._t, t)
        return True

    def tilt(self, t: float) -> tuple[float, float] | None:
        """base_link's (roll, pitch) at ``t``, bias taken off; None without a recent
        sample (or when disabled)."""
        if not self.cfg.enabled or self.raw is None or t - self._t > self.cfg.max_age_s:
            return None
        return self.raw[0] - self.bias[0], self.raw[1] - self.bias[1]

    def compensator(self, t: float, roll: float, pitch: float) -> bool:
        """The compensator's (roll, pitch) of base_link (rad) at the end of a scan the
        robot stood still through. Returns whether it calibrated the IMU."""
        lim = math.radians(self.cfg.compensator_range_deg)
        if (
            not self.cfg.calibrate
            or self.raw is None
            or t - self._t > self.cfg.max_age_s
            or not (abs(roll) < lim and abs(pitch) < lim)
        ):
            return False
        n = self.calibrations
        b = (self.raw[0] - roll, self.raw[1] - pitch)
        c = self._compensated
        self._compensated = ((c[0] * n + b[0]) / (n + 1), (c[1] * n + b[1]) / (n + 1))
        self.calibrations = n + 1
        return True

    def tilted(self, lever: tuple[float, float, float], t: float) -> tuple[float, float, float]:
        """A point ``lever`` in base_link (m) on the robot as tilted now, in the frame
        of base_link's yaw alone: its x, y are the horizontal lever arm, its z the
        height above base_link. Untilted without a tilt."""
        tilt = self.tilt(t)
        if tilt is None:
            return lever
        p = rot_zyx(tilt[0], tilt[1], 0.0) @ np.asarray(lever, dtype=np.float64)
        return float(p[0]), float(p[1]), float(p[2])

    def lever(self, lever: tuple[float, float, float], t: float) -> tuple[float, float]:
        """The horizontal lever arm of ``lever`` as tilted now (see :meth:`tilted`)."""
        x, y, _ = self.tilted(lever, t)
        return x, y
