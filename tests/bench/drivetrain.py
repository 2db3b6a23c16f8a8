"""What the simulated drivetrain alone needs to stand still, so that a stop figure can
be read as software reaction plus physics rather than as one number."""

from __future__ import annotations

import math

import numpy as np

from services.sim.robot import RobotConfig, RobotState, step
from services.sim.terrain import TerrainConfig, build_terrain


def braking(v0: float, still: float, cfg: RobotConfig | None = None) -> tuple[float, float]:
    """Seconds and metres from a zero command at ``v0`` (m/s, body) until the body
    moves slower than ``still``, on flat ground, under the simulator's own robot model
    (its lag and acceleration limit): the floor under any stop the software achieves."""
    cfg = cfg or RobotConfig()
    flat = build_terrain(
        np.array([-50.0, -5.0, 50.0, 5.0]),
        TerrainConfig(slope_pct=0.0, bump_rms=0.0, margin=1.0),
        0,
    )
    rng = np.random.default_rng(0)
    wheel = v0 / (1.0 - cfg.slip_long)
    s = RobotState(v=v0, v_wheel=wheel)
    t, dt = 0.0, 0.001
    while abs(s.v) >= still and t < 30.0:
        s = step(s, 0.0, 0.0, dt, flat, rng, cfg)
        t += dt
    return t, math.hypot(s.x, s.y)
