"""Scanner client against the FARO emulator on a virtual CAN bus.

Each test gets its own channel; the ``rig`` fixture stops what it started and the
``no_leaks`` fixture fails a test that leaves a bus channel or a thread behind.
Waits are on bus frames or events with timeouts, never sleeps.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable, Iterator

import can
import can.interfaces.virtual as virtual
import pytest

from services.scanner.can_codec import ScanProfile, ScanState
from services.scanner.client import AckTimeout, CommandRejected, ScannerClient, ScannerStatus
from services.scanner.emulator import FaroEmulator, FaroFaults, default_scan_duration_s

PROFILE = ScanProfile(resolution_index=4, quality=2)
SCAN_S = 0.3


def leaks(threads_before: set[threading.Thread], channel_prefix: str) -> list[str]:
    """Threads started and bus channels opened since, still alive."""
    found = [f"thread {t.name}" for t in threading.enumerate() if t not in threads_before]
    with virtual.channels_lock:
        found += [f"bus channel {c}" for c in virtual.channels if str(c).startswith(channel_prefix)]
    return found


@pytest.fixture
def no_leaks() -> Iterator[str]:
    """Yields a unique channel name; fails the test if anything it opened survives."""
    prefix = f"faro-test-{uuid.uuid4().hex[:8]}"
    before = set(threading.enumerate())
    yield prefix
    left = leaks(before, prefix)
    assert not left, f"test leaked: {left}"


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0
        self._lock = threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            return self.t

    def set(self, t: float) -> None:
        with self._lock:
            self.t = t


class Rig:
    """Emulator (in its thread) and client, each on its own bus of one channel."""

    def __init__(self, channel: str) -> None:
        self.channel = channel
        self.buses: list[can.BusABC] = []
        self.emulators: list[FaroEmulator] = []
        self.completed: list[tuple[int, ScanProfile]] = []
        self.completed_event = threading.Event()

    def _bus(self) -> can.BusABC:
        bus = can.Bus(interface="virtual", channel=self.channel)
        self.buses.append(bus)
        return bus

    def _on_complete(self, scan_id: int, profile: ScanProfile) -> None:
        self.completed.append((scan_id, profile))
        self.completed_event.set()

    def start(
        self,
        faults: FaroFaults | None = None,
        now: Callable[[], float] = time.monotonic,
        scan_s: float = SCAN_S,
        **client_kw: float,
    ) -> ScannerClient:
        emulator = FaroEmulator(
            self._bus(),
            now=now,
            scan_duration_s=lambda _p: scan_s,
            status_period_s=0.02,
            faults=faults,
            on_scan_complete=self._on_complete,
            inclination_deg=lambda: (1.234, -0.5),
        )
        client_bus = self._bus()
        emulator.start()
        self.emulators.append(emulator)
        # Generous watchdogs by default: a loaded CI machine must not trip them.
        kw = {"ack_timeout_s": 0.1, "retries": 2, "stuck_timeout_s": 1.0, "status_timeout_s": 1.0}
        kw.update(client_kw)
        return ScannerClient(client_bus, now=now, **kw)  # type: ignore[arg-type]

    def close(self) -> None:
        for e in self.emulators:
            e.stop()
        for b in self.buses:
            b.shutdown()


@pytest.fixture
def rig(no_leaks: str) -> Iterator[Rig]:
    r = Rig(no_leaks)
    yield r
    r.close()


def until(
    client: ScannerClient, pred: Callable[[ScannerStatus], bool], timeout_s: float = 2.0
) -> ScannerStatus:
    """Process frames (blocking on the bus) until ``pred`` holds; fail after timeout."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        st = client.poll(0.02)
        if pred(st):
            return st
    pytest.fail(f"condition not met within {timeout_s} s; status {client.status}")


def test_scan_runs_to_completion(rig: Rig) -> None:
    client = rig.start()
    sid = client.start_scan(PROFILE)
    seen = []
    while client.status.state == ScanState.SCANNING:
        seen.append(until(client, lambda _s: True).progress_pct)
        assert len(seen) < 500
    st = client.status
    assert st.state == ScanState.DONE and st.progress_pct == 100 and st.error == ""
    assert seen == sorted(seen) and any(0 < p < 100 for p in seen)
    assert st.inclinometer is not None and st.inclinometer.scan_id == sid
    assert (st.inclinometer.pitch_deg, st.inclinometer.roll_deg) == pytest.approx((1.234, -0.5))
    assert rig.completed_event.wait(1.0)
    assert rig.completed == [(sid, PROFILE)]


def test_next_scan_gets_a_new_id(rig: Rig) -> None:
    client = rig.start()
    first = client.start_scan(PROFILE)
    assert client.wait_finished(2.0).state == ScanState.DONE
    second = client.start_scan(PROFILE)
    assert second != first
    assert client.wait_finished(2.0).state == ScanState.DONE
    assert [sid for sid, _ in rig.completed] == [first, second]


@pytest.mark.parametrize(
    "faults", [FaroFaults(lose_first_acks=1), FaroFaults(lose_first_commands=2)]
)
def test_lost_ack_is_retried(rig: Rig, faults: FaroFaults) -> None:
    client = rig.start(faults)
    sid = client.start_scan(PROFILE)
    assert client.wait_finished(2.0).state == ScanState.DONE
    assert rig.completed == [(sid, PROFILE)]  # the retry did not start a second scan


def test_no_ack_ever_fails_within_the_timeout(rig: Rig) -> None:
    client = rig.start(FaroFaults(no_ack=True))
    t0 = time.monotonic()
    with pytest.raises(AckTimeout, match="no ACK for InitiateScan after 3 attempts"):
        client.start_scan(PROFILE)
    assert time.monotonic() - t0 < 3 * 0.1 + 0.25
    assert client.status.state == ScanState.IDLE
    assert rig.completed == []


def test_device_error_is_reported(rig: Rig) -> None:
    client = rig.start(FaroFaults(error_code=42, error_at_pct=30.0))
    client.start_scan(PROFILE)
    st = client.wait_finished(2.0)
    assert st.state == ScanState.ERROR
    assert "error code 42 at 30%" in st.error
    assert rig.completed == []


def test_stuck_scan_is_reported(rig: Rig) -> None:
    client = rig.start(FaroFaults(stuck_at_pct=40.0), stuck_timeout_s=0.2)
    client.start_scan(PROFILE)
    st = client.wait_finished(3.0)
    assert st.state == ScanState.ERROR
    assert "stuck at 40%" in st.error
    assert rig.completed == []


def test_pause_resume(rig: Rig) -> None:
    client = rig.start(scan_s=0.5, stuck_timeout_s=0.2)
    client.start_scan(PROFILE)
    until(client, lambda s: s.progress_pct >= 10)
    client.pause()
    paused = until(client, lambda s: s.state == ScanState.PAUSED)
    # Paused past the stuck timeout: no progress, and no false "stuck" error.
    st = client.poll(0.3)
    assert st.state == ScanState.PAUSED and st.progress_pct - paused.progress_pct <= 2
    client.resume()
    assert client.wait_finished(2.0).state == ScanState.DONE


def test_stop_aborts_and_never_reports_done(rig: Rig) -> None:
    client = rig.start(scan_s=0.4)
    client.start_scan(PROFILE)
    until(client, lambda s: s.progress_pct >= 10)
    client.stop()
    assert client.status.state == ScanState.IDLE
    st = client.poll(0.5)  # longer than the scan would have taken
    assert st.state == ScanState.IDLE and st.error == ""
    assert rig.completed == []


def test_second_scan_while_busy_is_rejected(rig: Rig) -> None:
    client = rig.start(scan_s=1.0)
    sid = client.start_scan(PROFILE)
    with pytest.raises(CommandRejected, match="BUSY"):
        client.start_scan(PROFILE, scan_id=sid + 1)
    client.stop()


def test_silent_scanner_is_reported(rig: Rig) -> None:
    client = rig.start(scan_s=1.0, stuck_timeout_s=5.0, status_timeout_s=0.3)
    client.start_scan(PROFILE)
    rig.emulators[0].stop()  # the device dies mid-scan
    st = client.wait_finished(2.0)
    assert st.state == ScanState.ERROR and "no status" in st.error


def test_sim_clock_drives_the_scan(rig: Rig) -> None:
    clock = FakeClock()
    client = rig.start(now=clock, scan_s=10.0, stuck_timeout_s=100.0, status_timeout_s=100.0)
    client.start_scan(PROFILE)
    clock.set(5.0)
    st = until(client, lambda s: s.progress_pct == 50)
    assert st.state == ScanState.SCANNING  # half the sim time: not done, whatever wall time
    clock.set(10.0)
    assert until(client, lambda s: s.state != ScanState.SCANNING).state == ScanState.DONE


def test_stuck_detection_on_the_sim_clock(rig: Rig) -> None:
    clock = FakeClock()
    client = rig.start(
        FaroFaults(stuck_at_pct=40.0),
        now=clock,
        scan_s=10.0,
        stuck_timeout_s=30.0,
        status_timeout_s=100.0,
    )
    client.start_scan(PROFILE)
    clock.set(8.0)
    until(client, lambda s: s.progress_pct == 40)
    clock.set(20.0)
    assert until(client, lambda s: s.progress_pct == 40).state == ScanState.SCANNING
    clock.set(40.0)
    st = until(client, lambda s: s.state == ScanState.ERROR)
    assert "stuck at 40% for 32.0 s" in st.error


def test_leak_check_catches_an_open_bus_and_a_thread() -> None:
    prefix = f"faro-test-{uuid.uuid4().hex[:8]}"
    before = set(threading.enumerate())
    bus = can.Bus(interface="virtual", channel=prefix)
    emulator = FaroEmulator(bus)
    emulator.start()
    try:
        found = leaks(before, prefix)
        assert f"bus channel {prefix}" in found and "thread faro-emulator" in found
    finally:
        emulator.stop()
        bus.shutdown()
    assert leaks(before, prefix) == []


def test_default_scan_time_is_plausible() -> None:
    # 1/4 resolution at 4x: the commonly quoted ~7.5 minutes.
    assert default_scan_duration_s(ScanProfile(resolution_index=2, quality=4)) == 450.0
