"""The Husky's IMU as a simulated device: a UM7-class attitude and heading reference
system (accelerometer, gyroscope and magnetometer fused by the unit's own filter),
reporting what the ``um7`` ROS driver publishes as sensor_msgs/Imu.

Error model (stated assumptions; the figures are the UM7's published accuracy, pitch
and roll +-1 deg static and +-3 deg dynamic, read as bounds):

- a **tilt bias** per axis, drawn once per run (turn-on bias, mounting after a bench
  levelling): normal with ``tilt_bias_sd_deg`` = 0.5 deg, so +-1 deg is two sigma;
- white **tilt noise**, ``tilt_noise_sd_deg`` = 0.05 deg per sample;
- the **dynamic error** of any accelerometer-levelled filter: the unit takes the
  specific force for gravity, so a forward acceleration ``a`` reads as a pitch of
  ``-a/g`` and a centripetal one ``v*w`` as a roll of ``v*w/g``; the unit's gyro-led
  filter rejects part of it, ``accel_leak`` = 0.5 gets through (at the Husky's
  1 m/s^2 that is about 3 deg, the dynamic bound);
- the gyroscope: ``gyro_noise_sd`` = 0.01 rad/s white and a per-run bias of
  ``gyro_bias_sd`` = 0.005 rad/s per axis, on the mean rate since the last reading
  (what a rate gyro's anti-alias filter passes; the body's rate within one physics
  step carries the turn's slip noise, white per step, which no gyro samples); yaw
  (magnetometer) off by ``yaw_sd_deg`` = 5 deg per run, since a magnetometer beside
  the motors is.

The noise comes from a generator of its own (seeded from the world's seed), so adding
or tuning the IMU never changes the world's other random draws, the truth included.
"""

from __future__ import annotations

import math
from typing import Annotated

import msgspec
import numpy as np

from common.geo import euler_zyx, rot_zyx, wrap_angle
from common.messages.base import Imu
from common.messages.core import IMU_FRAME, NonNegative
from common.robot import ImuMount
from services.sim.robot import RobotState

G = 9.80665


class ImuConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The simulated UM7 (see the module's docstring for where each figure comes from)."""

    enabled: bool = True
    """Simulate the IMU."""
    rate_hz: Annotated[float, msgspec.Meta(gt=0, le=200)] = 10.0
    """Samples per sim second (the um7 driver's default rate is 20 Hz; 10 Hz is plenty
    for a tilt that changes over metres of ground and halves the bus load at 20x real
    time)."""
    tilt_bias_sd_deg: NonNegative = 0.5
    """The SD of the tilt bias per axis, drawn once per run (deg): +-1 deg static is two
    sigma."""
    tilt_noise_sd_deg: NonNegative = 0.05
    """White tilt noise per sample (deg)."""
    accel_leak: Annotated[float, msgspec.Meta(ge=0, le=1)] = 0.5
    """The share of the specific force the unit reads as tilt: pitch ``-a_long/g``, roll
    ``v*w/g`` (0.5 at the Husky's 1 m/s² is the +-3 deg dynamic bound)."""
    gyro_noise_sd: NonNegative = 0.01
    """The gyroscope's white noise (rad/s)."""
    gyro_bias_sd: NonNegative = 0.005
    """The SD of the gyroscope's bias per axis, drawn once per run (rad/s)."""
    yaw_sd_deg: NonNegative = 5.0
    """The SD of the yaw's (magnetometer's) error, drawn once per run (deg): beside the
    motors; nothing fuses it."""


class ImuModel:
    """Turns the true motion into UM7 readings; one instance per world (its biases are
    the unit's for the whole run)."""

    def __init__(self, cfg: ImuConfig, seed: int, mount: ImuMount | None = None) -> None:
        self.cfg = cfg
        m = mount or ImuMount()
        self._mount = rot_zyx(m.roll_rad, m.pitch_rad, m.yaw_rad)
        self.rng = np.random.default_rng([seed, 0x1A7])  # 0x1A7: "IMU", its own stream
        self.tilt_bias = self.rng.normal(0.0, math.radians(cfg.tilt_bias_sd_deg), 2)
        self.gyro_bias = self.rng.normal(0.0, cfg.gyro_bias_sd, 3)
        self.yaw_bias = float(self.rng.normal(0.0, math.radians(cfg.yaw_sd_deg)))
        self._prev: tuple[float, RobotState] | None = None

    def read(self, t: float, s: RobotState) -> Imu:
        """The reading at sim time ``t`` (s) of a robot in true state ``s``."""
        c = self.cfg
        dt = 0.0 if self._prev is None else t - self._prev[0]
        prev = s if self._prev is None or dt <= 0 else self._prev[1]
        self._prev = (t, s)
        a_long = (s.v - prev.v) / dt if dt > 0 else 0.0
        a_lat = s.v * s.w  # centripetal, towards the turn's centre (+y turning left)
        d_roll, d_pitch = wrap_angle(s.roll - prev.roll), wrap_angle(s.pitch - prev.pitch)
        d_yaw = float(wrap_angle(s.yaw - prev.yaw))
        rate = (float(d_roll) / dt, float(d_pitch) / dt, d_yaw / dt) if dt > 0 else (0.0, 0.0, s.w)
        # the unit's own frame, turned by its mounting on base_link
        t_roll, t_pitch, t_yaw = euler_zyx(rot_zyx(s.roll, s.pitch, s.yaw) @ self._mount)
        sp, cp = math.sin(t_pitch), math.cos(t_pitch)
        sr, cr = math.sin(t_roll), math.cos(t_roll)
        noise = math.radians(c.tilt_noise_sd_deg)
        n = self.rng.normal(0.0, 1.0, 5)
        roll = t_roll + self.tilt_bias[0] + noise * n[0] + c.accel_leak * a_lat / G
        pitch = t_pitch + self.tilt_bias[1] + noise * n[1] - c.accel_leak * a_long / G
        g = self.gyro_bias + c.gyro_noise_sd * n[2:5]
        return Imu(
            stamp_ns=round(t * 1e9),
            frame_id=IMU_FRAME,
            roll=float(wrap_angle(roll)),
            pitch=float(wrap_angle(pitch)),
            yaw=float(wrap_angle(t_yaw + self.yaw_bias)),
            wx=rate[0] + float(g[0]),
            wy=rate[1] + float(g[1]),
            wz=rate[2] + float(g[2]),
            # the specific force: acceleration less gravity, in the body frame
            ax=a_long - G * sp,
            ay=a_lat + G * cp * sr,
            az=G * cp * cr,
            tilt_var=math.radians(c.tilt_bias_sd_deg) ** 2 + noise**2,
        )
