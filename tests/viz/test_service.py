"""The dashboard's shell on a real Zenoh session: bad messages cost a warning, never
the service; what it logs lands in the recording."""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

import msgspec

from common import keys
from common.clock import WallClock
from common.field import FieldLayout
from common.messages.base import LaserScan
from common.messages.core import Array
from common.messages.mission import MissionPhase, MissionState
from common.messages.nav import PoseEstimate
from common.messages.scan import ScannerState, ScannerStatus
from common.service import Context
from common.transport import Bus
from services.planner.core import plan as make_plan
from services.viz.config import VizConfig
from services.viz.service import VizService
from tests.viz import rrd
from tests.viz.test_traits_view import THREE, TINY, write


def wait_until(pred: object, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():  # type: ignore[operator]
            return True
        time.sleep(0.05)
    return False


def test_bad_messages_are_dropped_and_the_rest_is_recorded(client_bus: Bus, tmp_path: Path) -> None:
    out = tmp_path / "live.rrd"
    ctx = Context("viz", "test", client_bus, WallClock(), logging.getLogger("viz"), tmp_path)
    svc = VizService(ctx, VizConfig(save=str(out), rate_hz=20.0))
    stop = threading.Event()
    t = threading.Thread(target=svc.run, args=(stop,))
    t.start()
    try:
        lying = Array(dtype="<f4", shape=(100,), data=b"\0" * 4)
        bad_scan = LaserScan(
            angle_min=0, angle_max=1, angle_increment=0.01, range_min=0, range_max=5, ranges=lying
        )
        scans = client_bus.publisher(keys.BASE_SCAN)
        poses = client_bus.publisher(keys.NAV_POSE)
        client_bus.put_raw(keys.NAV_POSE.key, b"\xc1 not msgpack")
        scans.put(bad_scan)
        assert wait_until(lambda: "lidar" in svc.failed, 10), "bad scan never reached the tick"
        for k in range(5):
            poses.put(PoseEstimate(stamp_ns=time.time_ns(), x=float(k), y=1.0, yaw=0.0))
            time.sleep(0.06)
        assert wait_until(lambda: len(svc.trail.points) >= 2, 10), "poses not logged"
        assert client_bus.decode_stats.by_key.get(keys.NAV_POSE.key) == 1
        assert t.is_alive()
    finally:
        stop.set()
        t.join(timeout=10)
    assert not t.is_alive()
    assert rrd.verify(out).returncode == 0
    paths = rrd.entity_paths(out)
    assert {"/robot/estimate", "/robot/trail/0000", "/robot/estimate/body"} <= paths
    assert "/robot/estimate/lidar" not in paths


def test_a_finished_scan_is_drawn_where_it_was_taken_not_where_the_robot_is(
    client_bus: Bus, tmp_path: Path
) -> None:
    """The scanner repeats its DONE until the next scan: a dashboard (re)started while
    the robot drives on must not draw that scan at the moving robot."""
    ctx = Context("viz", "test", client_bus, WallClock(), logging.getLogger("viz"), tmp_path)
    svc = VizService(ctx, VizConfig(save=str(tmp_path / "live.rrd")))
    at_2 = PoseEstimate(stamp_ns=1, x=2.0, y=1.0, yaw=0.0)
    driving = PoseEstimate(stamp_ns=2, x=5.0, y=1.0, yaw=0.0, v=0.5)

    def done(scan_id: int) -> ScannerStatus:
        return ScannerStatus(state=ScannerState.DONE, scan_id=scan_id, file=f"s{scan_id}.e57")

    # scan 1 finished before this dashboard started; the robot is driving on: not drawn
    svc._put("pose", driving)
    svc._put("scanner", done(1))
    svc.tick()
    assert "scan" in svc.failed and svc._jobs.empty()
    # scan 2 seen being taken at x = 2, finished after the robot moved: drawn, from x = 2
    svc.failed.clear()
    svc._put("pose", at_2)
    svc._put("scanner", ScannerStatus(state=ScannerState.SCANNING, scan_id=2, progress=0.5))
    svc.tick()
    svc._put("pose", driving)
    svc._put("scanner", done(2))
    svc.tick()
    assert "scan" not in svc.failed and svc._jobs.qsize() == 1
    assert 2 not in svc._scan_poses


def test_a_done_missions_traits_are_drawn_on_the_plans_plots(
    client_bus: Bus, tmp_path: Path
) -> None:
    plan = make_plan(msgspec.toml.decode(TINY.read_bytes(), type=FieldLayout))
    out = tmp_path / "live.rrd"
    ctx = Context("viz", "test", client_bus, WallClock(), logging.getLogger("viz"), tmp_path)
    svc = VizService(ctx, VizConfig(save=str(out)))
    write(tmp_path / "m1" / "traits.csv", THREE)
    svc._put("plan", plan)
    svc._put("state", MissionState(stamp_ns=1, mission="m1", phase=MissionPhase.DONE))
    for _ in range(2):  # the plan's field is found on the worker, then the traits drawn
        svc.tick()
        while not svc._jobs.empty():
            job = svc._jobs.get_nowait()
            assert job is not None
            job()
    svc.out.close()
    assert not svc.failed
    assert "/field/traits/height" in rrd.entity_paths(out)
