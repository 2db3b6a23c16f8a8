"""The scanner service as a process, driving the FARO emulator over its (virtual) CAN
bus; the test plays the simulator's renderer."""

from __future__ import annotations

from pathlib import Path

import pytest

from common import keys
from common.client import wait_alive
from common.messages.scan import ScannerReply, ScannerState, ScanProfile, StartScan
from common.messages.sim import RenderReply, RenderRequest
from common.rpc import until_served
from common.transport import Bus, RpcError
from tests.conftest import Procs, record


def start(procs: Procs, ep: str, bus: Bus, tmp: Path, *sets: str) -> None:
    args = ["--set", "backend=sim", "--set", f"storage_dir='{tmp / 'card'}'"]
    args += ["--set", "sim_scan_time_s=1.0"]
    for s in sets:
        args += ["--set", s]
    procs.service("services.scanner", ep, *args, log=tmp / "scanner.log")
    assert wait_alive(bus.session, {"scanner"}, timeout=20)


def serve_render(bus: Bus, fail: bool = False) -> list[RenderRequest]:
    seen: list[RenderRequest] = []

    def render(req: RenderRequest) -> RenderReply:
        seen.append(req)
        if fail:
            raise RuntimeError("disk full")
        Path(req.path).write_bytes(b"e57")
        return RenderReply(path=req.path, points=3, pitch=0.01, roll=-0.02, render_s=0.0)

    bus.serve(keys.SIM_RENDER, render)
    return seen


def start_scan(bus: Bus, scan_id: int, resolution: int = 4, project: str = "") -> ScannerReply:
    cmd = StartScan(profile=ScanProfile(scan_id=scan_id, resolution=resolution), project=project)
    # the queryable comes up a moment after the liveliness token
    return until_served(lambda: bus.call(keys.SCANNER_CMD, cmd, timeout=5), 10.0)


def test_a_scan_goes_into_its_projects_folder_and_a_path_out_of_the_card_is_refused(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    # progress, DONE, the file and the inclinometer on every backend: tests/conformance
    renders = serve_render(client_bus)
    status = client_bus.latest(keys.SCANNER_STATUS)
    start(procs, router_endpoint, client_bus, tmp_path)
    with pytest.raises(RpcError, match="project"):  # a path out of the card: refused
        start_scan(client_bus, 7, project="../elsewhere")
    start_scan(client_bus, 7, project="survey-1")
    done = status.wait_for(lambda s: s.state == ScannerState.DONE, timeout=20)
    assert done is not None and done.scan_id == 7
    assert Path(done.file) == (tmp_path / "card" / "survey-1" / "Scan_00007.e57").resolve()
    assert Path(done.file).read_bytes() == b"e57"
    assert [r.scan_id for r in renders] == [7]


def test_a_status_stamped_after_a_retry_is_answered_speaks_of_the_retry(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    # the mission tells a retried scan's statuses from the previous attempt's DONE
    # (same scan id, republished every tick) by the scanner's stamp on its answer
    serve_render(client_bus)
    statuses = record(client_bus, keys.SCANNER_STATUS)
    start(procs, router_endpoint, client_bus, tmp_path)
    start_scan(client_bus, 3)
    assert statuses.wait_for(lambda s: s.state == ScannerState.DONE, timeout=20)
    reply = start_scan(client_bus, 3)
    assert statuses.wait_for(lambda s: s.stamp_ns > reply.stamp_ns, timeout=10)
    after = [s for s in statuses if s.stamp_ns > reply.stamp_ns]
    assert after[0].state == ScannerState.SCANNING, after[0]
    assert statuses.wait_for(
        lambda s: s.state == ScannerState.DONE and s.stamp_ns > reply.stamp_ns, timeout=20
    )


def test_a_scan_that_cannot_be_stored_fails(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    serve_render(client_bus, fail=True)
    status = client_bus.latest(keys.SCANNER_STATUS)
    start(procs, router_endpoint, client_bus, tmp_path)
    start_scan(client_bus, 9)
    err = status.wait_for(lambda s: s.state in (ScannerState.ERROR, ScannerState.DONE), timeout=20)
    assert err is not None and err.state == ScannerState.ERROR


def test_bad_resolution_is_rejected_with_the_field_named(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    start(procs, router_endpoint, client_bus, tmp_path)
    with pytest.raises(RpcError, match=r"ScanProfile\.resolution: 1/3"):
        start_scan(client_bus, 1, resolution=3)
