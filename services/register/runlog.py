"""A finished (or stopped) survey as registration reads it: ``runs/<mission>/mission.db``
opened read-only, its plan, and every done scan's file and recorded pose.

The mission log is never written here: it is opened with SQLite's ``mode=ro``, so a
registration that fails or is killed cannot lose or corrupt it. Every problem with
the input (no database, not a mission log, a scan file missing, a bad pose) raises
:class:`RunError` with one line naming the file and what is wrong.

Scan files: a step's ``file`` is where the scanner stored the scan (on its card). It
is used when it exists; otherwise the file of the same name is looked for in the
given ``scan_dirs``, then in ``RUN_DIR/scans`` and ``RUN_DIR`` (a card copied next to
the log on another machine).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path

import msgspec

from common.geo import rot_zyx
from common.messages.plan import PlanResult
from common.missionlog import MissionLogError, Step, read_run
from common.poses import F64, PoseError, scanner_pose
from common.robot import Robot
from services.register.pipeline import ScanInput


class RunError(ValueError):
    """The run folder cannot be registered; the message names the file and the cause."""


class Placement(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How a recorded navigation pose places the scanner (paper eq. 1).

    ``lever``: the scanner's optical centre in base_link (m). ``mount_yaw_deg``: the
    scanner's zero azimuth from base_link x. ``antenna_height``: the GNSS antennas'
    height above base_link (m) when navigation computes base_link from them with a
    *planar* lever arm (the EKF without an IMU): on a tilted robot the antennas
    lean ``antenna_height * tilt`` sideways of base_link, which this corrects with the
    inclinometer's pitch and roll, or, where navigation tilted the lever arms by the
    IMU (the step's ``nav_roll``, ``nav_pitch``), corrects what the IMU got wrong. All
    three are the robot description's (:meth:`of`).
    """

    lever: tuple[float, float, float]
    mount_yaw_deg: float
    antenna_height: float

    @classmethod
    def of(cls, robot: Robot) -> Placement:
        """The placement of ``robot``'s scanner, navigated by its antennas."""
        s = robot.scanner
        return cls(lever=s.xyz, mount_yaw_deg=s.yaw_deg, antenna_height=robot.antenna_height)


@dataclasses.dataclass(frozen=True)
class RunData:
    """The mission row, its plan (None when the log holds none), its steps and events,
    and whether the log has an altitude (the navigation pose's z; a planar estimate
    records 0 throughout)."""

    run_dir: Path
    mission: dict[str, object]
    plan: PlanResult | None
    steps: list[Step]
    events: list[tuple[int, str, str]]
    has_altitude: bool

    @property
    def done(self) -> list[Step]:
        return [s for s in self.steps if s.status == "done"]


def load_run(run_dir: str | Path) -> RunData:
    """Read ``run_dir/mission.db`` read-only; raises RunError."""
    run = Path(run_dir)
    try:
        db, data, _ = read_run(run)
    except MissionLogError as exc:
        raise RunError(str(exc)) from None
    assert data.mission is not None  # read_run refuses an empty mission table
    mission, steps, events = dict(data.mission), data.steps, data.events
    plan = None
    text = mission.pop("plan_json")
    if text:
        try:
            plan = msgspec.json.decode(str(text), type=PlanResult)
        except msgspec.DecodeError as exc:
            raise RunError(f"{db}: mission.plan_json is not a plan: {exc}") from None
    done = [s for s in steps if s.status == "done"]
    has_alt = any((s.mean_z or 0.0) != 0.0 or (s.sd_z or 0.0) != 0.0 for s in done)
    return RunData(run, mission, plan, steps, events, has_alt)


def find_scan(step: Step, run_dir: Path, scan_dirs: Sequence[Path] = ()) -> Path:
    """The scan file of ``step`` (see the module docstring); raises RunError."""
    if not step.file:
        raise RunError(f"scan {step.scan_id}: the mission log records no file for it")
    recorded = Path(step.file)
    if recorded.is_file():
        return recorded
    where = [*scan_dirs, run_dir / "scans", run_dir]
    for d in where:
        if (d / recorded.name).is_file():
            return d / recorded.name
    looked = ", ".join(str(d) for d in where)
    raise RunError(f"scan {step.scan_id}: file {recorded} not found (also looked in {looked})")


def nav_pose(step: Step, place: Placement, has_altitude: bool = True) -> F64:
    """4x4 ``field <- scanner`` from the step's recorded pose (``pose_*``; the means
    over the scan in a log older than those columns) and inclinometer (paper eq. 1,
    :func:`common.poses.scanner_pose`), base_link corrected for the planar antenna
    lever (see :class:`Placement`). Raises RunError naming the scan."""
    old = step.pose_x is None
    x, y = (step.mean_x, step.mean_y) if old else (step.pose_x, step.pose_y)
    yaw, z_rec = (step.mean_yaw, step.mean_z) if old else (step.pose_yaw, step.pose_z)
    vals = (x, y, yaw, step.pitch, step.roll)
    if any(v is None for v in vals):
        raise RunError(f"scan {step.scan_id}: the mission log has no pose or tilt for it")
    x, y, yaw, pitch, roll = (float(v) for v in vals)  # type: ignore[arg-type]
    z = float(z_rec or 0.0) if has_altitude else 0.0
    try:
        m = scanner_pose(x, y, z, yaw, pitch, roll, place.lever, math.radians(place.mount_yaw_deg))
    except PoseError as exc:
        raise RunError(f"scan {step.scan_id}: {exc}") from None
    if place.antenna_height:
        # the antennas sit at R (0, 0, h) from base_link, a planar EKF takes them at
        # (0, 0, h): its base_link is off by the horizontal part of R e_z * h. R e_z is
        # the scanner's z axis too (the mount turns only about z); the compensator's
        # pitch and roll hold about the scanner's own yaw, not the base's
        lean = m[:3, 2] * place.antenna_height
        if step.nav_roll is not None and step.nav_pitch is not None:
            # navigation took off the lean of the IMU's tilt already: the compensator's
            # (0.015 deg) replaces it, as what the IMU got wrong
            imu = rot_zyx(step.nav_roll, step.nav_pitch, yaw)[:, 2] * place.antenna_height
            lean = lean - imu
        m[:2, 3] -= lean[:2]
    return m


def scan_inputs(run: RunData, place: Placement, scan_dirs: Sequence[Path] = ()) -> list[ScanInput]:
    """A :class:`.pipeline.ScanInput` per done scan: its file and its navigation pose,
    what a real robot records. Raises RunError."""
    if not run.done:
        raise RunError(f"{run.run_dir / 'mission.db'}: no scan is done in this mission")
    return [
        ScanInput(
            path=find_scan(s, run.run_dir, scan_dirs),
            nav_pose=nav_pose(s, place, run.has_altitude),
            name=f"scan_{s.scan_id:03d}",
        )
        for s in run.done
    ]
