"""``phenorover register RUN_DIR`` on a small stored mission: a mission log written
through the mission service's own MissionLog, scans rendered by the simulator, the
navigation poses a planar EKF would record (off by the antennas' lean on a tilted
robot, plus noise). Nothing runs a mission: the report comes from what is stored."""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path

import laspy
import msgspec
import numpy as np
import pytest

from common.field import load_field
from common.geo import rot_zyx
from services.mission.log import MissionLog
from services.planner.core import plan
from services.register.cli import main, run_register
from services.register.io import read_registered_e57
from services.register.poses import euler_zyx
from services.register.report import build_report
from services.register.runlog import Placement, RunError, load_run, nav_pose, scan_inputs
from services.sim.render import ScanSettings, write_e57
from services.sim.robot import RobotState
from services.sim.truth_file import ScanTruth, write_truth
from services.sim.world import World

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"
ANTENNA_H = 1.10


def _planar_ekf_xy(state: RobotState) -> tuple[float, float]:
    """Where a planar EKF puts base_link: the antennas' mean minus their planar lever."""
    lean = rot_zyx(state.roll, state.pitch, state.yaw)[:, 2] * ANTENNA_H
    return state.x + lean[0], state.y + lean[1]


@pytest.fixture(scope="module")
def mission_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
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
        write_e57(path, scan.points, scan.intensity, name=path.stem)
        write_truth(
            path,
            ScanTruth(
                stamp_ns=k,
                scanner_pose=true.tolist(),
                x=state.x,
                y=state.y,
                z=state.z,
                roll=state.roll,
                pitch=state.pitch,
                yaw=state.yaw,
            ),
        )
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


def test_navigation_pose_undoes_the_planar_antenna_lever(mission_dir: Path) -> None:
    run = load_run(mission_dir)
    inputs = scan_inputs(run, Placement(antenna_height=ANTENNA_H))
    for s, inp in zip(run.done, inputs, strict=True):
        assert inp.true_pose is not None
        err = np.linalg.norm(inp.nav_pose[:3, 3] - inp.true_pose[:3, 3])
        assert err < 0.05  # the recorded noise only
        naive = nav_pose(s, Placement(antenna_height=0.0))
        tilt = math.hypot(s.pitch or 0.0, s.roll or 0.0)
        # without the correction the error grows with the tilt (1.1 m * tilt)
        if tilt > math.radians(1.0):
            assert np.linalg.norm(naive[:3, 3] - inp.true_pose[:3, 3]) > err


def test_register_writes_e57_laz_and_report(mission_dir: Path) -> None:
    reg = run_register(mission_dir)
    out = mission_dir
    for name in ("registered.e57", "registered.laz", "utm.laz", "report.json", "report.md"):
        assert (out / name).is_file(), name
    for name in ("layout_route.png", "stationary.png", "registration_hist.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert not list(out.glob(".*part*")), "a temporary file was left behind"

    # the E57 reads back with the registration's poses, one scan per location
    back = read_registered_e57(out / "registered.e57")
    assert [b.name for b in back] == [s.name for s in reg.report.scans]
    for b, p in zip(back, reg.c2c_poses, strict=True):
        np.testing.assert_allclose(b.pose, p, atol=1e-9)

    las = laspy.read(out / "utm.laz")
    assert las.header.parse_crs().to_epsg() == 32617  # Georgia: UTM 17N
    assert 2e5 < float(np.min(las.x)) < 8e5 and 3.7e6 < float(np.min(las.y)) < 3.8e6

    rep = json.loads((out / "report.json").read_text())
    assert rep["navigation"]["done"] == len(back)
    assert rep["registration"]["scans"] == len(back)
    truth_rows = {r["method"]: r for r in rep["registration"]["vs_truth"]}
    nav_err = truth_rows["navigation"]["points"]["mean_cm"]
    c2c_err = truth_rows["c2c"]["points"]["mean_cm"]
    assert 0 < nav_err < 10 and 0 < c2c_err < 10
    md = (out / "report.md").read_text()
    assert "Stationary errors per scan location" in md and "Nav. sensors + C2C" in md
    assert "![registration_hist.png](registration_hist.png)" in md


def test_report_from_the_stored_log_alone(mission_dir: Path) -> None:
    rep = build_report(load_run(mission_dir), None, {})
    rows = rep["stationary"]
    assert [r["status"] for r in rows] == ["done"] * len(rows)
    # planned points were offset by (2, -1) cm plus the antennas' lean: cm, not m
    assert all(0.5 < r["distance_to_planned_cm"] < 15 for r in rows)
    assert rep["navigation"]["route_m"] > 0 and rep["registration"] is None


def test_missing_scan_file_is_one_line(mission_dir: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "copy"
    run.mkdir()
    src = sqlite3.connect(mission_dir / "mission.db")
    dst = sqlite3.connect(run / "mission.db")
    src.backup(dst)
    dst.execute("UPDATE steps SET file = '/nowhere/Scan_00002.e57' WHERE idx = 1")
    dst.commit()
    src.close()
    dst.close()
    with pytest.raises(RunError, match=r"scan 2: file /nowhere/Scan_00002.e57 not found"):
        scan_inputs(load_run(run), Placement())
    assert main([str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Scan_00002.e57 not found" in err[0]


def test_corrupt_mission_db_is_one_line(tmp_path: Path, capsys) -> None:
    (tmp_path / "mission.db").write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(RunError, match="not a readable mission log"):
        load_run(tmp_path)
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "mission.db" in err[0]


def test_nav_pose_is_eq1_with_the_inclinometer(mission_dir: Path) -> None:
    s = load_run(mission_dir).done[0]
    m = nav_pose(s, Placement(antenna_height=0.0))
    roll, pitch, yaw = euler_zyx(m)
    assert (roll, pitch, yaw) == pytest.approx((s.roll, s.pitch, s.mean_yaw), abs=1e-12)
    base = np.array([s.mean_x, s.mean_y, s.mean_z], dtype=np.float64)
    np.testing.assert_allclose(m[:3, 3], base + m[:3, 2] * 1.0)
