"""The IMU's tilt in navigation: the antennas' lever arms in 3D, samples under
acceleration refused, the bias taken off by the scanner's compensator; and the
registration's pre-alignment with a tilted navigation pose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from common.geo import rot_zyx
from common.missionlog import Step
from common.robot import ImuMount, default_robot
from services.nav.config import Mounts
from services.nav.ekf import EkfConfig, Localizer
from services.nav.tilt import Tilt, TiltConfig
from services.register.runlog import Placement, nav_pose
from services.sim.imu import G, ImuConfig, ImuModel
from services.sim.robot import RobotState, body_to_field

ROLL, PITCH, YAW = math.radians(1.5), math.radians(-1.0), 0.7
MOUNTS = Mounts.of(default_robot())


def _standing(tilt: Tilt | None) -> np.ndarray:
    """nav's (x, y) of a robot standing tilted at (5, 3), from its two antennas'
    true positions, with the lever arms tilted by ``tilt`` (None: planar)."""
    s = RobotState(x=5.0, y=3.0, yaw=YAW, roll=ROLL, pitch=PITCH)
    truth = body_to_field(s, np.array(MOUNTS.levers))
    loc = Localizer(EkfConfig())
    for k in range(30):
        t = 0.1 * k
        loc.update_odometry(t, 0.0, 0.0, 1e-6, 1e-6, still=True)
        loc.update_heading(t, YAW, 0.005)
        for lever, p in zip(MOUNTS.levers, truth, strict=True):
            planar = tilt.lever(lever, t) if tilt else lever[:2]
            loc.update_antenna(t, p[:2], np.eye(2) * 1e-4, planar)
    return loc.x[:2] - np.array([5.0, 3.0])


def _fed(cfg: TiltConfig, roll: float, pitch: float, n: int = 30) -> Tilt:
    tilt = Tilt(cfg, ImuMount())
    for k in range(n):
        t = 0.1 * k
        tilt.motion(t, 0.0, 0.0)
        tilt.imu(t, roll, pitch)
    return tilt


def test_tilted_levers_put_base_link_under_the_leaning_antennas() -> None:
    planar = np.hypot(*_standing(None))
    tilted = np.hypot(*_standing(_fed(TiltConfig(), ROLL, PITCH)))
    # 1.1 m antennas leaning 1.8 deg: 3.5 cm; the tilt takes it to the filter's noise
    assert planar > 0.03
    assert tilted < 0.002


def test_samples_taken_under_acceleration_are_refused_and_the_last_good_tilt_stands() -> None:
    tilt = _fed(TiltConfig(), ROLL, PITCH)
    fused = tilt.tilt(2.9)
    assert fused == pytest.approx((ROLL, PITCH), abs=1e-6)
    # braking at 1 m/s^2: the UM7 reads it as 3 deg of pitch, which must not get in
    for k in range(5):
        t = 3.0 + 0.1 * k
        tilt.motion(t, 0.5 - 0.1 * k, 0.0)
        assert not tilt.imu(t, ROLL, PITCH + math.radians(3.0))
    assert tilt.rejected == 5
    assert tilt.tilt(3.4) == pytest.approx((ROLL, PITCH), abs=1e-6)
    # a stale tilt is not used: the lever stays upright
    assert tilt.tilt(3.4 + 2.5) is None
    assert tilt.lever((0.0, 0.0, 1.1), 6.0) == (0.0, 0.0)


def test_the_compensator_takes_the_imus_bias_off_within_its_range_only() -> None:
    bias = (math.radians(0.6), math.radians(-0.4))
    tilt = _fed(TiltConfig(), ROLL + bias[0], PITCH + bias[1])
    assert tilt.compensator(2.9, ROLL, PITCH)
    got = tilt.tilt(2.9)
    assert got is not None
    assert math.degrees(abs(got[0] - ROLL)) < 1e-6
    assert math.degrees(abs(got[1] - PITCH)) < 1e-6
    assert tilt.calibrations == 1
    # beyond the compensator's +-2 deg its reading is not a measurement
    assert not tilt.compensator(2.9, math.radians(2.5), 0.0)
    assert not _fed(TiltConfig(calibrate=False), ROLL, PITCH).compensator(2.9, ROLL, PITCH)


def test_a_yawed_imu_mount_is_turned_back_to_base_links_roll_and_pitch() -> None:
    mount = ImuMount(yaw_deg=90.0)
    r_imu = rot_zyx(ROLL, PITCH, YAW) @ rot_zyx(0.0, 0.0, math.pi / 2)
    roll_i = math.atan2(r_imu[2, 1], r_imu[2, 2])
    pitch_i = -math.asin(r_imu[2, 0])
    tilt = Tilt(TiltConfig(), mount)
    tilt.motion(0.0, 0.0, 0.0)
    tilt.imu(0.0, roll_i, pitch_i)
    assert tilt.tilt(0.0) == pytest.approx((ROLL, PITCH), abs=1e-9)


def test_the_simulated_um7_has_a_run_bias_noise_and_reads_acceleration_as_tilt() -> None:
    cfg = ImuConfig()
    a, b = ImuModel(cfg, seed=3), ImuModel(cfg, seed=3)
    assert np.array_equal(a.tilt_bias, b.tilt_bias)  # the unit's, for the whole run
    assert not np.array_equal(a.tilt_bias, ImuModel(cfg, seed=4).tilt_bias)
    s = RobotState(roll=ROLL, pitch=PITCH, yaw=YAW)
    reads = [a.read(0.1 * k, s) for k in range(200)]
    roll = np.mean([r.roll for r in reads]) - ROLL
    pitch = np.mean([r.pitch for r in reads]) - PITCH
    assert roll == pytest.approx(a.tilt_bias[0], abs=math.radians(0.02))
    assert pitch == pytest.approx(a.tilt_bias[1], abs=math.radians(0.02))
    # speeding up by 1 m/s^2 reads as the nose going up by leak * a / g
    quiet = ImuModel(ImuConfig(tilt_noise_sd_deg=0.0, tilt_bias_sd_deg=0.0), seed=0)
    quiet.read(0.0, s)
    faster = quiet.read(0.1, RobotState(roll=ROLL, pitch=PITCH, yaw=YAW, v=0.1))
    assert faster.pitch - PITCH == pytest.approx(-cfg.accel_leak * 1.0 / G, rel=1e-6)
    assert faster.az == pytest.approx(G * math.cos(PITCH) * math.cos(ROLL))


def test_registration_replaces_the_imus_lean_by_the_compensators() -> None:
    """A scan recorded by a tilted navigation whose IMU was off by a bias: the
    pre-alignment puts the scanner where it truly stood, as with a planar one."""
    robot = default_robot()
    place = Placement.of(robot)
    s = RobotState(x=5.0, y=3.0, z=0.2, yaw=YAW, roll=ROLL, pitch=PITCH)
    bias = (math.radians(0.8), math.radians(-0.5))
    h = place.antenna_height
    lean_true = rot_zyx(ROLL, PITCH, YAW)[:, 2] * h
    imu = (ROLL + bias[0], PITCH + bias[1])
    lean_imu = rot_zyx(imu[0], imu[1], YAW)[:, 2] * h
    common = dict(idx=0, scan_id=1, cand_id=1, x=5.0, y=3.0, yaw=YAW, status="done", attempts=1)
    base = dict(mean_z=s.z, mean_yaw=YAW, pitch=PITCH, roll=ROLL)
    # nav put base_link where the antennas lean, less the IMU's idea of the lean
    tilted = Step(
        **common,  # type: ignore[arg-type]
        **base,  # type: ignore[arg-type]
        mean_x=5.0 + lean_true[0] - lean_imu[0],
        mean_y=3.0 + lean_true[1] - lean_imu[1],
        nav_roll=imu[0],
        nav_pitch=imu[1],
    )
    planar = Step(
        **common,  # type: ignore[arg-type]
        **base,  # type: ignore[arg-type]
        mean_x=5.0 + lean_true[0],
        mean_y=3.0 + lean_true[1],
    )
    want = body_to_field(s, np.array(robot.scanner.xyz))
    for step in (tilted, planar):
        assert nav_pose(step, place)[:3, 3] == pytest.approx(want, abs=1e-4)


def test_an_antenna_whose_tilted_lever_changes_every_fix_is_still_one_antenna() -> None:
    """The filter counts a run of rejections per antenna: after a real jump (0.3 m)
    it re-initialises from the agreeing fixes even though the tilt moves the lever a
    little at every fix."""
    loc = Localizer(EkfConfig())
    lever = MOUNTS.levers[1]
    t = 0.0
    for k in range(100):
        t = 0.1 * k
        loc.update_odometry(t, 0.0, 0.0, 1e-6, 1e-6, still=True)
        loc.update_heading(t, 0.0, 0.005)
        loc.update_antenna(t, np.array([lever[0], 0.0]), np.eye(2) * 1e-4, lever[:2], name="2")
    for k in range(40):  # not standing: a run of 10 re-initialises
        t += 0.1
        loc.update_odometry(t, 0.0, 0.0, 1e-6, 1e-6, still=False)
        loc.update_heading(t, 0.0, 0.005)
        wobble = (lever[0], 1e-4 * math.sin(k))  # a lever the IMU's noise moves
        loc.update_antenna(t, np.array([lever[0] + 0.3, 0.0]), np.eye(2) * 1e-4, wobble, name="2")
    assert loc.x[0] == pytest.approx(0.3, abs=0.02)
