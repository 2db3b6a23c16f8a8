"""A scan in the simulated world through the whole device path: typed command ->
scanner service -> CAN frames -> FARO emulator -> the simulator renders the E57 onto
the 'card' -> DONE with the inclinometer reading."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from common import keys
from common.client import wait_alive
from common.messages.scan import ScannerState
from common.pointcloud import read_e57
from common.transport import Bus
from tests.conftest import Procs
from tests.integration.test_scanner_service import start_scan


def test_scan_of_engr_lands_as_e57_with_pose_and_tilt(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    common = ("--clock", "sim", "--field", "engr")
    procs.service(
        "services.sim",
        router_endpoint,
        *common,
        "--set",
        "real_time_factor=5.0",
        "--set",
        f"scan_dir='{tmp_path / 'card'}'",  # the sim renders scans only under it
        log=tmp_path / "sim.log",
    )
    procs.service(
        "services.scanner",
        router_endpoint,
        *common,
        "--set",
        "backend=sim",
        "--set",
        f"storage_dir='{tmp_path / 'card'}'",
        "--set",
        "sim_scan_time_s=20.0",
        log=tmp_path / "scanner.log",
    )
    assert wait_alive(client_bus.session, {"sim", "scanner"}, timeout=30)
    truth = client_bus.latest(keys.SIM_TRUTH)
    status = client_bus.latest(keys.SCANNER_STATUS)
    assert truth.wait_for(lambda t: True, timeout=20)
    start_scan(client_bus, 1)
    prog = status.wait_for(
        lambda s: s.state == ScannerState.SCANNING and s.progress > 0.2, timeout=30
    )
    assert prog is not None
    done = status.wait_for(lambda s: s.state == ScannerState.DONE, timeout=60)
    assert done is not None and done.scan_id == 1
    t = truth.get()
    assert t is not None
    # the inclinometer reads the true tilt within its 0.015 deg noise (and int16 frames)
    assert abs(math.degrees(done.pitch - t.pitch)) < 0.1
    assert abs(math.degrees(done.roll - t.roll)) < 0.1
    (scan,) = read_e57(Path(done.file))
    pts, intensity, pose = scan.points, scan.intensity, scan.pose
    assert len(pts) > 100_000 and len(intensity) == len(pts)
    assert np.allclose(pose, np.eye(4))  # as a scanner stores it: in its own frame
    r = np.linalg.norm(pts, axis=1)
    assert r.min() >= 0.6 and r.max() <= 70.0
