"""Simulated Hokuyo UST-05LX 2D lidar (the paper's obstacle sensor).

The scan plane is the lidar's x-y plane, tilted with the robot (so on a slope it can
see the ground ahead); beams go counter-clockwise from -135 deg to +135 deg about the
lidar's +z, 0 deg straight ahead. Ranges are metres as float32, ``inf`` where there
is no valid return (nothing within range, or closer than the minimum range).
"""

from __future__ import annotations

import math
from typing import Annotated

import msgspec
import numpy as np

from common.arrays import F32, F64
from common.geo import rot_zyx
from common.messages.core import NonNegative, Positive
from common.robot import LidarMount, default_robot
from services.sim.robot import RobotState, pose_matrix
from services.sim.scene import Scene


class LidarConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Hokuyo UST-05LX (metres, degrees). Field of view, step and range from Hokuyo's
    datasheet (270 deg, 0.25 deg, 0.06-5 m, accuracy +-40 mm, read here as a 2-sigma
    band: sigma 20 mm). Where it sits is the robot description's ``[lidar]``."""

    fov_deg: Annotated[float, msgspec.Meta(gt=0, le=360)] = 270.0
    """The field of view (deg)."""
    step_deg: Annotated[float, msgspec.Meta(gt=0, le=10)] = 0.25
    """The angle between beams (deg)."""
    min_range: NonNegative = 0.06
    """The shortest range measured (m)."""
    max_range: Positive = 5.0
    """The longest range measured (m)."""
    sigma: NonNegative = 0.02
    """The range noise's 1-sigma (m)."""


def beam_angles(cfg: LidarConfig) -> F64:
    """Beam angles (rad) in the lidar frame, first to last."""
    n = math.floor(cfg.fov_deg / cfg.step_deg + 1e-9) + 1
    out: F64 = np.radians(-cfg.fov_deg / 2 + np.arange(n) * cfg.step_deg)
    return out


def lidar_pose(state: RobotState, mount: LidarMount) -> F64:
    """4x4 transform field <- lidar of a lidar at ``mount`` on the robot at ``state``."""
    m = np.eye(4)
    m[:3, :3] = rot_zyx(0.0, 0.0, mount.yaw_rad)
    m[:3, 3] = mount.xyz
    out: F64 = pose_matrix(state) @ m
    return out


def scan(
    scene: Scene,
    state: RobotState,
    cfg: LidarConfig,
    rng: np.random.Generator,
    mount: LidarMount | None = None,
) -> F32:
    """One sweep from the robot at ``state`` of a lidar at ``mount`` (default: the
    shipped robot's): ranges (n_beams,) float32, inf = none."""
    return noisy(
        true_ranges(scene, lidar_pose(state, mount or default_robot().lidar), cfg), cfg, rng
    )


def true_ranges(scene: Scene, pose: F64, cfg: LidarConfig) -> F64:
    """The exact distances (n_beams,) float64, inf = none, of a sweep from the lidar at
    ``pose`` (4x4, field <- lidar, :func:`lidar_pose`)."""
    if cfg.max_range <= cfg.min_range:
        raise ValueError(f"lidar max_range={cfg.max_range} <= min_range={cfg.min_range}")
    a = beam_angles(cfg)
    local = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    t, _, _ = scene.cast(pose[:3, 3], local @ pose[:3, :3].T, cfg.max_range)
    return t


def noisy(t: F64, cfg: LidarConfig, rng: np.random.Generator) -> F32:
    """What the lidar reports of the exact distances ``t``: ranges with its noise,
    none outside its range (float32, inf)."""
    r = t + cfg.sigma * rng.standard_normal(len(t))
    r = np.where(np.isfinite(t) & (r >= cfg.min_range), np.minimum(r, cfg.max_range), np.inf)
    return r.astype(np.float32)
