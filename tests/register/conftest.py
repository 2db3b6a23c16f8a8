"""A small stored survey for the registration tests: a mission log written through the
mission service's own MissionLog, scans rendered by the simulator with their truth
files, and the navigation poses a planar EKF would record (off by the antennas' lean
on a tilted robot, plus noise)."""

from __future__ import annotations

import math
import shutil
import sqlite3
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.field import load_field
from common.geo import rot_zyx
from common.pointcloud import PosedScan, write_e57
from common.robot import default_robot
from services.mission.log import MissionLog
from services.planner.core import plan
from services.register.runlog import Placement
from services.sim.render import ScanSettings
from services.sim.robot import RobotState
from services.sim.truth_file import scan_truth, write_truth
from services.sim.world import World

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"
ANTENNA_H = Placement.of(default_robot()).antenna_height


def _planar_ekf_xy(state: RobotState) -> tuple[float, float]:
    """Where a planar EKF puts base_link: the antennas' mean minus their planar lever."""
    lean = rot_zyx(state.roll, state.pitch, state.yaw)[:, 2] * ANTENNA_H
    return state.x + lean[0], state.y + lean[1]


@pytest.fixture(scope="session")
def mission_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``runs/tiny-1`` of a survey of the tiny field: ``mission.db`` and the scans on
    a card beside it (``../card``), each with the simulator's ``.truth.json``."""
    layout, field = load_field(TINY)
    world = World(layout, field)
    pr = plan(layout, field=field)
    run = tmp_path_factory.mktemp("runs") / "tiny-1"
    card = run.parent / "card"
    card.mkdir()
    rng = np.random.default_rng(11)
    log = MissionLog(run / "mission.db")
    xy = [c for c in pr.candidates if c.id in set(pr.selected)]
    log.create(
        "tiny-1",
        "tiny",
        0,
        msgspec.json.encode(pr).decode(),
        [(k + 1, c.id, c.x, c.y, 0.0) for k, c in enumerate(xy)],
    )
    for k, c in enumerate(xy):
        state = world.settle(RobotState(x=c.x + 0.02, y=c.y - 0.01, yaw=0.01 * k))
        true = world.scanner_pose(state)
        scan = world.render_scan(true, ScanSettings(step_deg=0.6), rng)
        path = card / f"Scan_{k + 1:05d}.e57"
        write_e57(path, [PosedScan.as_scanned(scan.points, scan.intensity, path.stem)])
        write_truth(path, scan_truth(k, true, state))
        ex, ey = _planar_ekf_xy(state)
        log.update(
            k,
            status="done",
            attempts=1,
            file=str(path),
            started_ns=10**9 * (60 * k),
            ended_ns=10**9 * (60 * k + 56),
            mean_x=ex + rng.normal(0, 0.005),
            mean_y=ey + rng.normal(0, 0.005),
            mean_z=state.z + rng.normal(0, 0.01),
            mean_yaw=state.yaw + math.radians(rng.normal(0, 0.2)),
            sd_x=0.004,
            sd_y=0.005,
            sd_z=0.01,
            sd_yaw=math.radians(0.4),
            pitch=state.pitch + math.radians(0.01),
            roll=state.roll - math.radians(0.01),
        )
    log.set_state("done")
    log.close()
    return run


def copy_run(src: Path, dst: Path) -> Path:
    """The mission log and the scans (with their truth files) of ``src`` under ``dst``,
    the log's scan paths pointing at the copies; no outputs of earlier registrations."""
    card = dst / "card"
    shutil.copytree(src.parent / "card", card)
    run = dst / src.name
    run.mkdir()
    a, b = sqlite3.connect(src / "mission.db"), sqlite3.connect(run / "mission.db")
    try:
        a.backup(b)
        rows = b.execute("SELECT idx, file FROM steps WHERE file IS NOT NULL").fetchall()
        for idx, file in rows:
            b.execute("UPDATE steps SET file = ? WHERE idx = ?", (str(card / Path(file).name), idx))
        b.commit()
    finally:
        a.close()
        b.close()
    return run
