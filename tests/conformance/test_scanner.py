"""The scanner contract, run against every CAN backend of the scanner service, each
driving the FARO emulator: ``sim`` (the emulator on a virtual bus inside the service),
``can-virtual`` (python-can's ``virtual`` interface, the hardware backend's code path
as on SocketCAN, the emulator on the far end of the channel) and ``can-slcan``
(python-can's ``slcan`` over a pseudo-terminal to ``faro-sim``'s SLCAN adapter end, as
``make hil`` runs it). SocketCAN itself is left out: this kernel has no ``vcan``.

Whatever the backend: a scan started with a profile reports progress, then DONE with
its id, its file on the card and the inclinometer's reading; a stopped scan is never
done nor stored; an error frame is one clear error; a lost ACK is retried; a device
that never answers is a clear error. One scanner per backend serves the module's
tests: each fault is aimed at a scan id of its own (the test plays the renderer)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import uuid
from collections.abc import Iterator
from pathlib import Path

import can
import pytest

from common import keys
from common.messages.scan import ScannerState, ScannerStatus, StopScan
from common.messages.sim import RenderRequest
from common.transport import Bus, RpcError
from services.scanner.config import ScannerConfig
from services.scanner.service import ScannerService
from services.scanner.sim.card import RenderedCard, emulate
from services.scanner.sim.config import FaroSimConfig
from services.scanner.sim.faro import FaroSim
from services.scanner.sim.faults import FaroFaults
from tests.conformance.conftest import Running, context, sessions
from tests.conftest import Record, record
from tests.integration.test_scanner_service import serve_render, start_scan

BACKENDS = ["sim", "can-virtual", "can-slcan"]
SCAN_S = 0.3  # every scan's duration (wall clock)
ERROR_ID, STUCK_ID, LOST_ACK_ID, NO_ACK_ID = 42, 30, 7, 99
FAULTS = FaroFaults(
    error_code=42,
    error_scan_ids=[ERROR_ID],
    stuck_at_pct=30.0,
    stuck_scan_ids=[STUCK_ID],
    lose_first_acks=1,
    lose_scan_ids=[LOST_ACK_ID],
    no_ack=True,
    no_ack_scan_ids=[NO_ACK_ID],
)


@dataclasses.dataclass
class Scanner:
    backend: str
    bus: Bus  # the test's: commands out, statuses in, renders answered
    status: Record[ScannerStatus]
    renders: list[RenderRequest]
    card: Path

    def of(self, scan_id: int) -> list[ScannerStatus]:
        return [s for s in self.status if s.scan_id == scan_id]

    def wait(self, scan_id: int, state: ScannerState, timeout: float = 10.0) -> ScannerStatus:
        got = self.status.wait_for(lambda s: s.scan_id == scan_id and s.state == state, timeout)
        assert got is not None, f"{self.backend}: scan {scan_id} never {state}: {self.of(scan_id)}"
        return got


def _device(
    backend: str, run: Running, stack: contextlib.ExitStack, bus: Bus, tmp: Path
) -> ScannerConfig:
    """The FARO emulator at the far end of ``backend``'s wire (its card's renders asked
    on ``bus``); the scanner config that reaches it."""
    card, ctx = tmp / "card", context(bus, "faro-sim", tmp)
    # wall-clock allowances a loaded machine keeps to: an ACK within 1 s, progress
    # within 2 s (a 0.3 s scan reports it every 50 ms)
    common = {"storage_dir": str(card), "status_hz": 20.0, "ack_timeout_s": 1.0}
    common |= {"stuck_timeout_s": 2.0}
    if backend == "sim":
        return ScannerConfig(backend="sim", sim_faults=FAULTS, sim_scan_time_s=SCAN_S, **common)  # type: ignore[arg-type]
    if backend == "can-virtual":
        channel = f"faro-conformance-{uuid.uuid4().hex[:8]}"
        far = can.Bus(interface="virtual", channel=channel)
        stack.callback(far.shutdown)
        emulator = emulate(ctx, far, RenderedCard(ctx, str(card), 0.36), FAULTS, SCAN_S)
        emulator.start()
        stack.callback(emulator.stop)
        return ScannerConfig(backend="can", interface="virtual", channel=channel, **common)  # type: ignore[arg-type]
    link = tmp / "hil" / "faro-can"
    faro = FaroSim(
        ctx, FaroSimConfig(link=str(link), storage_dir=str(card), faults=FAULTS, scan_time_s=SCAN_S)
    )
    run.start(faro, "faro-sim")
    return ScannerConfig(backend="can", interface="slcan", channel=str(link), **common)  # type: ignore[arg-type]


@pytest.fixture(scope="module", params=BACKENDS)
def scanner(
    request: pytest.FixtureRequest, router_endpoint: str, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Scanner]:
    backend: str = request.param
    tmp = tmp_path_factory.mktemp(backend)
    with sessions(router_endpoint, "sim", "faro-sim", "scanner") as (buses, stack, run):
        bus, far_bus, scanner_bus = buses
        renders = serve_render(bus)
        cfg = _device(backend, run, stack, far_bus, tmp)
        rig = Scanner(backend, bus, record(bus, keys.SCANNER_STATUS), renders, tmp / "card")
        run.start(ScannerService(context(scanner_bus, "scanner", tmp), cfg), "scanner")
        yield rig


def test_a_scan_reports_progress_then_done_with_its_file(scanner: Scanner) -> None:
    start_scan(scanner.bus, 1)
    moving = scanner.status.wait_for(
        lambda s: s.scan_id == 1 and s.state == ScannerState.SCANNING and 0 < s.progress < 1, 10.0
    )
    assert moving is not None, scanner.of(1)
    done = scanner.wait(1, ScannerState.DONE)
    assert done.progress == 1.0 and done.error == ""
    assert Path(done.file) == (scanner.card / "Scan_00001.e57").resolve()
    assert Path(done.file).read_bytes() == b"e57"
    assert math.isclose(done.pitch, 0.01, abs_tol=1e-4)
    assert math.isclose(done.roll, -0.02, abs_tol=1e-4)
    assert [r.scan_id for r in scanner.renders].count(1) == 1


def test_a_stopped_scan_is_never_done_nor_stored(scanner: Scanner) -> None:
    start_scan(scanner.bus, 2)
    running = scanner.status.wait_for(lambda s: s.scan_id == 2 and s.progress > 0, 10.0)
    assert running is not None, "scan 2 never ran: there would be nothing to stop"
    scanner.bus.call(keys.SCANNER_CMD, StopScan(), timeout=5.0)
    scanner.wait(2, ScannerState.IDLE)
    start_scan(scanner.bus, 3)  # the next scan runs through: the stopped one is over
    scanner.wait(3, ScannerState.DONE)
    assert all(s.state != ScannerState.DONE for s in scanner.of(2)), scanner.of(2)
    assert 2 not in [r.scan_id for r in scanner.renders]


def test_an_error_frame_is_one_clear_error(
    scanner: Scanner, caplog: pytest.LogCaptureFixture
) -> None:
    with caplog.at_level("WARNING", logger="scanner"):
        start_scan(scanner.bus, ERROR_ID)
        err = scanner.wait(ERROR_ID, ScannerState.ERROR)
        n = len(scanner.status)  # and it stays so, said once
        assert scanner.status.until(lambda ss: len(ss) > n + 3, timeout=5.0)
    assert err.error == "scanner error code 42 at 50%" and err.file == ""
    errors = {s.error for s in scanner.of(ERROR_ID) if s.state == ScannerState.ERROR}
    assert errors == {err.error}
    said = [r for r in caplog.records if r.getMessage().startswith("scanner error")]
    assert len(said) == 1, caplog.text


def test_a_scan_stuck_without_progress_is_an_error(scanner: Scanner) -> None:
    start_scan(scanner.bus, STUCK_ID)
    err = scanner.wait(STUCK_ID, ScannerState.ERROR)
    assert err.error.startswith("scan stuck at 30%") and err.file == ""
    # the device still holds it: ended, the scanner takes the next scan
    scanner.bus.call(keys.SCANNER_CMD, StopScan(), timeout=5.0)


def test_a_lost_ack_is_retried(scanner: Scanner, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level("WARNING", logger="services.scanner.client"):
        start_scan(scanner.bus, LOST_ACK_ID)
    scanner.wait(LOST_ACK_ID, ScannerState.DONE)
    retried = [r.getMessage() for r in caplog.records if "no ACK for" in r.getMessage()]
    # (a loaded machine may miss a later ACK's second too: the first is the lost one)
    assert retried[:1] == ["no ACK for InitiateScan (attempt 1/3)"], retried


def test_a_device_that_never_answers_is_a_clear_error(scanner: Scanner) -> None:
    # an error reply naming the ACK, not a call left unanswered
    with pytest.raises(RpcError, match=r"scanner: no ACK for InitiateScan after 3 attempts"):
        start_scan(scanner.bus, NO_ACK_ID)
