"""``phenorover register RUN_DIR`` on a small stored mission (``conftest.mission_dir``:
a mission log written through the mission service's own MissionLog, scans rendered by
the simulator, the navigation poses a planar EKF would record). Nothing runs a
mission: the report comes from what is stored."""

from __future__ import annotations

import dataclasses
import json
import math
import sqlite3
from pathlib import Path

import laspy
import msgspec
import numpy as np
import pytest

from common.geo import euler_zyx
from common.pointcloud import read_e57
from common.robot import default_robot
from phenorover.eval.register.truth import read_truth, true_pose
from services.register.cli import main, run_register
from services.register.report import build_report
from services.register.runlog import Placement, RunError, load_run, nav_pose, scan_inputs

PLACE = Placement.of(default_robot())
PLANAR = msgspec.structs.replace(PLACE, antenna_height=0.0)  # no lean correction


def test_navigation_pose_undoes_the_planar_antenna_lever(mission_dir: Path) -> None:
    run = load_run(mission_dir)
    inputs = scan_inputs(run, PLACE)
    for s, inp in zip(run.done, inputs, strict=True):
        truth = read_truth(inp.path)  # the test's own check: registration never reads it
        assert truth is not None
        true = true_pose(truth, inp.name)
        err = np.linalg.norm(inp.nav_pose[:3, 3] - true[:3, 3])
        assert err < 0.05  # the recorded noise only
        naive = nav_pose(s, PLANAR)
        tilt = math.hypot(s.pitch or 0.0, s.roll or 0.0)
        # without the correction the error grows with the tilt (1.1 m * tilt)
        if tilt > math.radians(1.0):
            assert np.linalg.norm(naive[:3, 3] - true[:3, 3]) > err


def test_register_writes_e57_laz_and_report(mission_dir: Path) -> None:
    reg = run_register(mission_dir)
    out = mission_dir
    for name in ("registered.e57", "registered.laz", "utm.laz", "report.json", "report.md"):
        assert (out / name).is_file(), name
    for name in ("layout_route.png", "stationary.png", "registration_hist.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert not list(out.glob(".*part*")), "a temporary file was left behind"

    # the E57 reads back with the registration's poses, one scan per location
    back = read_e57(out / "registered.e57")
    assert [b.name for b in back] == [s.name for s in reg.report.scans]
    for b, p in zip(back, reg.c2c_poses, strict=True):
        np.testing.assert_allclose(b.pose, p, atol=1e-9)

    las = laspy.read(out / "utm.laz")
    assert las.header.parse_crs().to_epsg() == 32617  # Georgia: UTM 17N
    assert 2e5 < float(np.min(las.x)) < 8e5 and 3.7e6 < float(np.min(las.y)) < 3.8e6

    rep = json.loads((out / "report.json").read_text())
    assert rep["navigation"]["done"] == len(back)
    assert rep["registration"]["scans"] == len(back)
    rows = {r["method"]: r for r in rep["registration"]["vs_reference"]}
    assert 0 <= rows["c2c"]["points"]["mean_cm"] < 10
    # scan point statistics need no reference: the target-based registration has them
    for method in ("navigation", "c2c", "target_based"):
        o = rows[method]["overlap"]
        assert o["radius_cm"] == 30.0 and o["pairs"] >= 1 and 0 < o["mean_cm"] <= o["max_cm"]
    # our own figures only: no truth, no paper's (both are the evaluation's)
    assert "vs_truth" not in rep["registration"] and "paper_cm" not in rep["registration"]
    assert (out / "register.toml").is_file() and rep["outputs"]["config"] == "register.toml"
    md = (out / "report.md").read_text()
    assert "Stationary errors per scan location" in md and "Nav. sensors + C2C" in md
    assert "Scan point statistics, as SCENE reports them" in md
    assert "![registration_hist.png](registration_hist.png)" in md


def test_report_from_the_stored_log_alone(mission_dir: Path) -> None:
    rep = build_report(load_run(mission_dir), None, {})
    rows = rep["stationary"]
    assert [r["status"] for r in rows] == ["done"] * len(rows)
    # the logged estimate against the planned point, in cm (the fixture stood the robot
    # 2 cm and -1 cm off, plus the antennas' lean and noise: centimetres, not metres)
    run = load_run(mission_dir)
    for r, st in zip(rows, run.steps, strict=True):
        assert st.mean_x is not None and st.mean_y is not None
        want = 100 * math.hypot(st.mean_x - st.x, st.mean_y - st.y)
        assert r["distance_to_planned_cm"] == pytest.approx(want, abs=0.01)
    assert max(r["distance_to_planned_cm"] for r in rows) > 0.5
    assert all(r["distance_to_planned_cm"] < 15 for r in rows)
    assert rep["navigation"]["route_m"] > 0 and rep["registration"] is None
    # the tiny field lists no sphere sites, and the report says so
    assert rep["targets"] == {
        "placement": "no sites listed in the field file: spheres found in the scans only",
        "sites": [],
    }


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
        scan_inputs(load_run(run), PLACE)
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


def test_nav_pose_takes_the_recorded_scan_pose_over_the_means(mission_dir: Path) -> None:
    s = load_run(mission_dir).done[0]
    assert s.pose_x is None  # this log predates the columns: the means place it
    moved = dataclasses.replace(
        s,
        pose_x=(s.mean_x or 0.0) + 0.1,
        pose_y=(s.mean_y or 0.0) - 0.2,
        pose_z=s.mean_z,
        pose_yaw=s.mean_yaw,
    )
    a, b = nav_pose(s, PLANAR), nav_pose(moved, PLANAR)
    np.testing.assert_allclose(b[:3, 3] - a[:3, 3], [0.1, -0.2, 0.0], atol=1e-9)
    turned = dataclasses.replace(moved, pose_yaw=(s.mean_yaw or 0.0) + 0.01)
    assert euler_zyx(nav_pose(turned, PLANAR))[2] == pytest.approx(euler_zyx(a)[2] + 0.01)


def test_nav_pose_is_eq1_with_the_inclinometer(mission_dir: Path) -> None:
    s = load_run(mission_dir).done[0]
    m = nav_pose(s, PLANAR)
    roll, pitch, yaw = euler_zyx(m)
    assert (roll, pitch, yaw) == pytest.approx((s.roll, s.pitch, s.mean_yaw), abs=1e-12)
    base = np.array([s.mean_x, s.mean_y, s.mean_z], dtype=np.float64)
    np.testing.assert_allclose(m[:3, 3], base + m[:3, 2] * PLACE.lever[2])
