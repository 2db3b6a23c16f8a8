"""Husky A200 skid-steer motion on the terrain, with slip, and its wheel-encoder view.

Frames (REP-103): ``base_link`` x forward, y left, z up; its origin is on the plane
through the four wheel contacts, midway between them, and the pose is given in the
``field`` frame with ZYX Euler angles (yaw, then pitch, then roll).

The drivetrain follows the commanded twist with a first-order lag under speed and
acceleration limits; those are the *wheel* velocities, which the encoders measure. The
body moves less than the wheels say:

- longitudinal slip: ``v = v_wheel * (1 - slip_long * soil)``;
- skid-steer turning wastes wheel motion scrubbing sideways, so the body yaws at
  ``yaw_efficiency`` of the rate the wheel speeds imply (lower on loose soil), with
  random fluctuation;
- uneven traction moves the instantaneous centre of rotation off the body centre by a
  slowly wandering offset, so a turn in place also translates the robot sideways. The
  paper blames its corner cross-track errors on exactly this ("Non-stationary error
  analysis": in-place rotations introduced a lateral displacement, worse on loose
  soil).

``soil`` scales every slip term: 1 is firm, tilled soil; 2-3 is loose or rocky ground.
The wheel geometry and the speed and acceleration limits are the robot description's
(:mod:`common.robot`); :class:`RobotConfig` holds what only a simulation has.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Annotated

import msgspec
import numpy as np
import numpy.typing as npt

from common.arrays import F64
from common.geo import rot_zyx, wrap_angle
from common.messages.core import NonNegative, Positive
from common.robot import Robot, default_robot
from services.sim.terrain import Terrain


class RobotConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """The Husky A200's drivetrain dynamics on soil (metres, seconds, radians). The
    slip and noise figures are assumptions sized to the paper's results (corner XTE of
    5-10 cm, heading settling within its 2 deg tolerance), not measurements.
    """

    tau: Positive = 0.15
    """The first-order lag of the motor speed loops (s)."""
    slip_long: Annotated[float, msgspec.Meta(ge=0, lt=1)] = 0.01
    """Longitudinal slip, a share of the wheel speed per unit soil."""
    yaw_efficiency: Annotated[float, msgspec.Meta(gt=0, le=1)] = 0.93
    """The body's yaw rate over the rate the wheel speeds imply, on firm soil (soil = 1):
    skid-steer scrubbing."""
    yaw_noise: NonNegative = 0.02
    """The relative random fluctuation of the yaw rate while turning (1/sqrt(Hz)), per
    unit soil."""
    icr_std: NonNegative = 0.03
    """The SD of the rotation centre's offset from the body centre (m), per unit soil."""
    icr_tau: Positive = 2.0
    """The correlation time of the rotation centre's offset (s)."""
    lateral_noise: NonNegative = 0.01
    """White lateral velocity noise while moving or turning (m/s per m/s or rad/s), per
    unit soil."""
    encoder_scale: Annotated[float, msgspec.Meta(gt=-0.5, lt=0.5)] = 0.005
    """The wheel encoders' relative scale error (the wheel radius on soil)."""
    encoder_v_std: NonNegative = 0.005
    """The encoders' white noise on the linear speed (m/s)."""
    encoder_w_std: NonNegative = 0.01
    """The encoders' white noise on the turn rate (rad/s)."""


@dataclasses.dataclass(frozen=True)
class RobotState:
    """True state: base_link pose in ``field`` (m, rad) and body velocities (m/s,
    rad/s, in base_link). ``v_wheel``/``w_wheel`` are the drivetrain velocities the
    wheels turn at (what the encoders see); ``icr`` is the current rotation-centre
    offset along x (m)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    v: float = 0.0
    w: float = 0.0
    v_wheel: float = 0.0
    w_wheel: float = 0.0
    icr: float = 0.0


def _toward(current: float, target: float, max_delta: float) -> float:
    return current + min(max(target - current, -max_delta), max_delta)


def settle(state: RobotState, terrain: Terrain, robot: Robot | None = None) -> RobotState:
    """``state`` with z, pitch and roll taken from the ground under the four wheels
    (``robot``'s track and wheelbase; default: the shipped robot)."""
    robot = robot or default_robot()
    hx, hy = robot.wheelbase / 2, robot.track / 2
    c, s = math.cos(state.yaw), math.sin(state.yaw)
    bx = np.array([hx, hx, -hx, -hx])  # front-left, front-right, rear-left, rear-right
    by = np.array([hy, -hy, hy, -hy])
    h = terrain.height(state.x + c * bx - s * by, state.y + s * bx + c * by)
    front, rear = (h[0] + h[1]) / 2, (h[2] + h[3]) / 2
    left, right = (h[0] + h[2]) / 2, (h[1] + h[3]) / 2
    # a rigid chassis on four contacts: the least-squares plane through them
    pitch = math.atan2(rear - front, robot.wheelbase)  # nose down is positive (REP-103)
    roll = math.atan2(left - right, robot.track)  # left side up is positive
    return dataclasses.replace(state, z=float(h.mean()), pitch=pitch, roll=roll)


def step(
    state: RobotState,
    cmd_v: float,
    cmd_w: float,
    dt: float,
    terrain: Terrain,
    rng: np.random.Generator,
    cfg: RobotConfig | None = None,
    soil: float = 1.0,
    robot: Robot | None = None,
) -> RobotState:
    """Advance the robot ``dt`` seconds under the commanded twist (m/s, rad/s), within
    ``robot``'s limits (default: the shipped robot).

    Raises ValueError for a non-positive or non-finite ``dt`` or a negative ``soil``.
    """
    cfg = cfg or RobotConfig()
    robot = robot or default_robot()
    lim = robot.limits
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a positive number of seconds, got {dt}")
    if not soil >= 0:
        raise ValueError(f"soil factor must be >= 0, got {soil}")
    tv = min(max(cmd_v if math.isfinite(cmd_v) else 0.0, -lim.max_speed), lim.max_speed)
    tw = min(max(cmd_w if math.isfinite(cmd_w) else 0.0, -lim.max_turn_rate), lim.max_turn_rate)
    k = 1.0 - math.exp(-dt / cfg.tau)
    vw = _toward(state.v_wheel, state.v_wheel + (tv - state.v_wheel) * k, lim.max_accel * dt)
    ww = _toward(state.w_wheel, state.w_wheel + (tw - state.w_wheel) * k, lim.max_turn_accel * dt)

    v = vw * (1.0 - min(cfg.slip_long * soil, 0.9))
    eff = max(1.0 - (1.0 - cfg.yaw_efficiency) * soil, 0.05)
    w = ww * eff * (1.0 + cfg.yaw_noise * soil * rng.standard_normal() / math.sqrt(dt))
    # Ornstein-Uhlenbeck wander of the rotation centre (exact discretisation)
    a = math.exp(-dt / cfg.icr_tau)
    icr_sd = cfg.icr_std * soil
    icr = state.icr * a + icr_sd * math.sqrt(1.0 - a * a) * rng.standard_normal()
    # turning about a centre offset by icr along x moves the body centre sideways
    lat = -icr * w
    lat += cfg.lateral_noise * soil * (abs(vw) + abs(ww)) * rng.standard_normal() / math.sqrt(dt)

    yaw_mid = state.yaw + 0.5 * w * dt
    c, s = math.cos(yaw_mid), math.sin(yaw_mid)
    # the slope tilts the body, so only cos(pitch) of the travel is horizontal
    cp = math.cos(state.pitch)
    x = state.x + (c * v * cp - s * lat) * dt
    y = state.y + (s * v * cp + c * lat) * dt
    moved = RobotState(
        x=x,
        y=y,
        z=state.z,
        roll=state.roll,
        pitch=state.pitch,
        yaw=float(wrap_angle(state.yaw + w * dt)),
        v=v,
        w=w,
        v_wheel=vw,
        w_wheel=ww,
        icr=icr,
    )
    return settle(moved, terrain, robot)


def encoder_twist(
    state: RobotState, rng: np.random.Generator, cfg: RobotConfig | None = None
) -> tuple[float, float]:
    """Linear and angular velocity (m/s, rad/s) as wheel odometry reports them: from
    the wheel speeds, so blind to slip, with a scale error and white noise."""
    cfg = cfg or RobotConfig()
    scale = 1.0 + cfg.encoder_scale
    v = state.v_wheel * scale + cfg.encoder_v_std * rng.standard_normal()
    w = state.w_wheel * scale + cfg.encoder_w_std * rng.standard_normal()
    return v, w


def pose_matrix(state: RobotState) -> F64:
    """4x4 transform field <- base_link."""
    m = np.eye(4)
    m[:3, :3] = rot_zyx(state.roll, state.pitch, state.yaw)
    m[:3, 3] = (state.x, state.y, state.z)
    return m


def body_to_field(state: RobotState, p_body: npt.ArrayLike) -> F64:
    """Field-frame position of base_link point(s) ``p_body`` (..., 3) through the full
    3D pose, so e.g. a GNSS antenna 1.1 m up moves ~2 cm sideways per degree of roll."""
    p = np.asarray(p_body, dtype=np.float64)
    r = rot_zyx(state.roll, state.pitch, state.yaw)
    out: F64 = p @ r.T + np.array([state.x, state.y, state.z])
    return out
