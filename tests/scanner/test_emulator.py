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
from services.scanner.sim.device import BusOffGate
from services.scanner.sim.emulator import FaroEmulator, FaroFaults, default_scan_duration_s

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
        # the client's end as the sim device wires it: sends fail while bus-off
        client_bus = BusOffGate(
            can.Bus(interface="virtual", channel=self.channel), emulator.bus_off
        )
        self.buses.append(client_bus)
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
    # a fail-safe only (the attempts take 0.3 s; the message counts them): without a
    # bound on them the call would never return
    assert time.monotonic() - t0 < 10.0
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


def test_faults_aimed_at_scan_ids_spare_the_others(rig: Rig) -> None:
    client = rig.start(
        FaroFaults(stuck_at_pct=40.0, stuck_scan_ids=[2], no_ack=True, no_ack_scan_ids=[3]),
        stuck_timeout_s=0.2,
    )
    assert client.start_scan(PROFILE, scan_id=1) == 1
    assert client.wait_finished(2.0).state == ScanState.DONE
    client.start_scan(PROFILE, scan_id=2)
    st = client.wait_finished(3.0)
    assert st.state == ScanState.ERROR and "stuck at 40%" in st.error
    client.stop()
    with pytest.raises(AckTimeout):
        client.start_scan(PROFILE, scan_id=3)
    assert client.start_scan(PROFILE, scan_id=4) == 4
    assert client.wait_finished(2.0).state == ScanState.DONE
    assert [sid for sid, _ in rig.completed] == [1, 4]


def test_lost_acks_counted_per_aimed_scan(rig: Rig) -> None:
    # three ACKs lost per aimed scan: more than one command's 1 + 2 attempts
    client = rig.start(FaroFaults(lose_first_acks=3, lose_scan_ids=[2, 3]))
    client.start_scan(PROFILE, scan_id=1)
    assert client.wait_finished(2.0).state == ScanState.DONE
    with pytest.raises(AckTimeout):
        client.start_scan(PROFILE, scan_id=2)
    # the device did start it; the fourth Initiate of scan 2 is acknowledged
    assert client.start_scan(PROFILE, scan_id=2) == 2
    assert client.wait_finished(2.0).state == ScanState.DONE
    with pytest.raises(AckTimeout):
        client.start_scan(PROFILE, scan_id=3)  # scan 3 has its own three


def test_bus_off_silences_the_device_and_fails_sends_then_recovers(rig: Rig) -> None:
    clock = FakeClock()
    client = rig.start(
        FaroFaults(bus_off_for_s=5.0, bus_off_scan_ids=[2]),
        now=clock,
        scan_s=10.0,
        stuck_timeout_s=100.0,
        status_timeout_s=100.0,
    )
    gate = rig.buses[-1]
    client.start_scan(PROFILE, scan_id=1)
    clock.set(10.0)
    assert until(client, lambda s: s.state != ScanState.SCANNING).state == ScanState.DONE
    client.start_scan(PROFILE, scan_id=2)  # acknowledged, then the bus goes off
    assert rig.emulators[0].bus_off() and gate.state == can.BusState.ERROR
    clock.set(13.0)
    st = client.poll(0.2)  # the device scans on but sends nothing
    assert st.state == ScanState.SCANNING and st.progress_pct < 30
    with pytest.raises(can.CanOperationError, match="bus-off"):
        gate.send(can.Message(arbitration_id=0x100))
    with pytest.raises(AckTimeout):
        client.pause()
    clock.set(16.0)  # 5 s later the node is back
    assert until(client, lambda s: s.progress_pct == 60).state == ScanState.SCANNING
    assert gate.state == can.BusState.ACTIVE
    clock.set(20.0)
    st = until(client, lambda s: s.state != ScanState.SCANNING)
    assert st.state == ScanState.DONE and st.inclinometer is not None
    clock.set(21.0)
    client.start_scan(PROFILE, scan_id=3)  # once only
    assert not rig.emulators[0].bus_off()


def test_a_long_bus_off_fails_the_scan_and_the_client_recovers(rig: Rig) -> None:
    clock = FakeClock()
    client = rig.start(
        FaroFaults(bus_off_for_s=5.0),
        now=clock,
        scan_s=10.0,
        stuck_timeout_s=100.0,
        status_timeout_s=2.0,
    )
    client.start_scan(PROFILE)
    client.poll(0.05)  # the status sent with the ACK, before the bus went off
    clock.set(3.0)
    st = until(client, lambda s: s.state == ScanState.ERROR)
    assert "no status from scanner" in st.error
    clock.set(5.0)
    client.stop()  # the device still runs the scan: end it, then start afresh
    clock.set(6.0)
    client.start_scan(PROFILE)
    clock.set(16.0)
    assert until(client, lambda s: s.state != ScanState.SCANNING).state == ScanState.DONE
