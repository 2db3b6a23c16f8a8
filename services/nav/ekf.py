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

import numpy as np
import numpy.typing as npt

from common.arrays import F64
from services.nav.ekf_config import EkfConfig
from services.nav.ekf_filter import CHI2_999, Filter, angle_residual
from services.nav.ekf_guard import check_antenna, check_heading, check_height, check_odometry
from services.nav.ekf_models import antenna_model

__all__ = ["CHI2_999", "EkfConfig", "Localizer"]


class Localizer(Filter):
    """The filter with its measurements: wheel odometry, each antenna's position, the
    compass heading and the height."""

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
            angle_residual,
        )

    def update_height(self, t: float, z: float, var: float) -> bool:
        """base_link height from one antenna's RTK height (already less the
        antenna's height above base_link) with its variance (m^2)."""
        var, bad = check_height(z, var, self.cfg.min_fix_sd_m)
        if not self._admit("height", t, bad):
            return False
        scaled = var * self._correlation_scale("height", t, position=True)
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
