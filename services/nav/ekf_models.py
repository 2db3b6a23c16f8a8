"""Models of the localization filter: the unicycle's motion and process noise, the
antenna's position through its lever arm, and base_link's height as a scalar filter
beside the planar one. Pure."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from common.arrays import F64
from services.nav.ekf_config import EkfConfig
from services.nav.ekf_guard import ConsistentRun

Model = tuple[Callable[[F64], F64], Callable[[F64], F64]]


def unicycle(x: F64, dt: float) -> tuple[F64, F64]:
    """The state ``[x, y, yaw, v, w]`` ``dt`` seconds on at constant velocities, and
    the Jacobian of that step."""
    px, py, yaw, v, w = (float(a) for a in x)
    c, s = math.cos(yaw + 0.5 * w * dt), math.sin(yaw + 0.5 * w * dt)
    f = np.eye(5)
    f[0, 2], f[0, 3], f[0, 4] = -v * dt * s, dt * c, -0.5 * v * dt * dt * s
    f[1, 2], f[1, 3], f[1, 4] = v * dt * c, dt * s, 0.5 * v * dt * dt * c
    f[2, 4] = dt
    return np.array([px + v * dt * c, py + v * dt * s, yaw + w * dt, v, w]), f


def motion_share(cfg: EkfConfig, v: float, w: float) -> float:
    """The share of the full position and heading process noise at body speeds
    ``v`` (m/s) and ``w`` (rad/s); 1 without dynamic process noise."""
    if not cfg.dynamic_process_noise:
        return 1.0
    moving = max(0.0, abs(v) - cfg.still_speed) + max(0.0, abs(w) - cfg.still_speed)
    return min(1.0, max(cfg.still_noise_share, moving / cfg.full_noise_speed))


def process_noise(
    cfg: EkfConfig, share: float, accel_share: float, dt: float, turned: float = 0.0
) -> F64:
    """Q over ``dt`` s: slip on position and heading (``share`` of it, by speed), the
    sideways slip of ``turned`` rad of turn, a random walk on the velocities
    (``accel_share`` of it)."""
    pos = share * cfg.pos_process_sd**2 * dt + cfg.turn_slip_sd**2 * abs(turned)
    return np.diag(
        [
            pos,
            pos,
            share * cfg.yaw_process_sd**2 * dt,
            accel_share * cfg.accel_sd**2 * dt,
            accel_share * cfg.yaw_accel_sd**2 * dt,
        ]
    )


def antenna_model(lever: tuple[float, float], lag: float) -> Model:
    """(h(x), its Jacobian) of an antenna at ``lever`` (x, y in base_link, m) seen
    ``lag`` seconds ago, for the state ``[x, y, yaw, v, w]`` (constant velocities)."""
    lx, ly = lever

    def hx(x: F64) -> F64:
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

    return hx, jac


class HeightFilter:
    """base_link's height in the field frame (m) and its variance (m^2; inf before
    the first measurement): the antennas' heights say nothing about x, y or yaw on
    a level robot, so they get a scalar filter of their own, gated like the rest."""

    def __init__(self) -> None:
        self.z = 0.0
        self.var = math.inf
        self._run = ConsistentRun()

    def update(self, z: float, var: float, scaled: float, gate: float | None, after: int) -> str:
        """Fuse height ``z`` of variance ``var`` (``scaled`` for correlated fixes):
        ``fused``, ``gate`` (refused: beyond ``gate``, a chi-square quantile, or None
        for no gate) or ``relocalized`` (re-initialised from ``after`` refusals in a
        row that agree with each other)."""
        if not math.isfinite(self.var):
            self.z, self.var = z, var
            return "fused"
        innov, s = np.array([z - self.z]), np.array([[self.var + var]])
        if gate is not None and float(innov[0] ** 2 / s[0, 0]) > gate:
            if self._run.add(innov, s, gate, np.subtract) < after:
                return "gate"
            self._run.clear()
            self.z, self.var = z, var
            return "relocalized"
        self._run.clear()
        k = self.var / (self.var + scaled)
        self.z += k * (z - self.z)
        self.var *= 1.0 - k
        return "fused"
