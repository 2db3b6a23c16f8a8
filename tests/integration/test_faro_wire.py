"""The scanner service's hardware backend (``backend = "can"``, ``interface =
"slcan"``, python-can) against the FARO emulator in another process, behind an SLCAN
link over a pseudo-terminal (``services.scanner.sim.faro``); the test plays the
simulator's renderer."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from common import keys
from common.client import wait_alive
from common.messages.scan import PauseScan, ScannerState
from common.messages.system import Health
from common.transport import Bus, RpcError
from tests.conftest import Procs, record
from tests.integration.test_scanner_service import serve_render, start_scan


def start(
    procs: Procs,
    ep: str,
    bus: Bus,
    tmp: Path,
    *faults: str,
    scan_s: float = 3.0,
    **scanner: str,
) -> None:
    """faro-sim (a scan takes ``scan_s``), then the scanner service on its link."""
    link, card = tmp / "hil" / "faro-can", tmp / "card"
    args = ["--set", f"link='{link}'", "--set", f"storage_dir='{card}'"]
    args += ["--set", f"scan_time_s={scan_s}"]
    for f in faults:
        args += ["--set", f"faults.{f}"]
    procs.service("services.scanner.sim.faro", ep, *args, log=tmp / "faro-sim.log")
    assert wait_alive(bus.session, {"faro-sim"}, timeout=20)  # up: the link is there
    assert link.is_symlink()
    sets = {"backend": "can", "interface": "slcan", "channel": f"'{link}'"}
    sets |= {"storage_dir": f"'{card}'", **scanner}
    args = [a for k, v in sets.items() for a in ("--set", f"{k}={v}")]
    procs.service("services.scanner", ep, *args, log=tmp / "scanner.log")
    assert wait_alive(bus.session, {"scanner"}, timeout=20)


def lines(log: Path, text: str) -> list[str]:
    return [line for line in log.read_text().splitlines() if text in line]


def test_bus_off_is_said_once_and_the_scan_goes_on_when_the_bus_is_back(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    serve_render(client_bus)
    status = client_bus.latest(keys.SCANNER_STATUS)
    health = record(client_bus, keys.HEALTH.at(service="scanner"))
    # a 5 s scan whose node is off for 3.5 s of it; silence is an error only after 10 s
    start(
        procs,
        router_endpoint,
        client_bus,
        tmp_path,
        "bus_off_for_s=3.5",
        scan_s=5.0,
        status_timeout_s="10.0",
    )
    start_scan(client_bus, 1)
    # Within its 3 x 0.5 s the client learns from the adapter's flags that the bus is
    # off (it polls them every 0.5 s), and the last attempt is refused at once.
    with pytest.raises(RpcError, match=r"no ACK for RecordPause.*sending failed: .*bus error"):
        client_bus.call(keys.SCANNER_CMD, PauseScan(), timeout=10)

    def bus_error(h: Health) -> int:
        return h.counters.get("can_bus_error", -1)

    def back(hs: list[Health]) -> bool:
        seen = [bus_error(h) for h in hs]
        return 1 in seen and 0 in seen[seen.index(1) :]

    assert health.until(back, timeout=10), "bus-off not reported, or the bus never came back"
    done = status.wait_for(lambda s: s.state != ScannerState.SCANNING and s.scan_id == 1, 20)
    assert done is not None and done.state == ScannerState.DONE, done
    log = tmp_path / "scanner.log"
    said = lines(log, "scanner CAN bus:")
    assert len(said) == 2, said
    assert "bus error" in said[0] and "adapter status flags 0xA6" in said[0]
    assert said[1].endswith("scanner CAN bus: back")


def test_a_silent_device_fails_the_scan_with_the_reason(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    serve_render(client_bus)
    status = client_bus.latest(keys.SCANNER_STATUS)
    start(procs, router_endpoint, client_bus, tmp_path, status_timeout_s="1.0")
    start_scan(client_bus, 2)
    assert status.wait_for(lambda s: s.state == ScannerState.SCANNING, timeout=10)
    faro = procs.procs[0]
    os.kill(faro.pid, signal.SIGSTOP)  # it holds the link but says nothing
    try:
        err = status.wait_for(lambda s: s.state != ScannerState.SCANNING, timeout=10)
    finally:
        os.kill(faro.pid, signal.SIGCONT)
    assert err is not None and err.state == ScannerState.ERROR, err
    assert "no status from scanner" in err.error and err.file == ""
