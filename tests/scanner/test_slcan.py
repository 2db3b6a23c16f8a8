"""The SLCAN adapter end (:class:`SlcanDevice`) over a real pseudo-terminal, driven by
python-can's own ``slcan`` interface, and the FARO emulator behind it.

Every frame that crosses the wire is parsed here from the raw SLCAN lines and decoded
with the DBC by cantools directly, not through our codec. Waits are on frames with
timeouts, never sleeps."""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import can
import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from services.scanner.can_codec import ScanProfile, ScanState
from services.scanner.client import AckTimeout, ScannerClient
from services.scanner.sim.emulator import FaroEmulator, FaroFaults
from services.scanner.sim.slcan_device import BUS_OFF_FLAGS, SlcanDevice
from services.scanner.slcan_host import SlcanHost
from tests.scanner.test_emulator import FakeClock, until

DBC = Path(__file__).resolve().parents[2] / "services" / "scanner" / "faro.dbc"
PROFILE = ScanProfile(resolution_index=4, quality=2)


def host_bus(dev: SlcanDevice, cls: type[can.BusABC] | None = None) -> can.BusABC:
    """The host's end as a user's config opens it: python-can's slcan at 500 kbit/s."""
    if cls is None:
        return can.Bus(interface="slcan", channel=dev.tty_path, bitrate=500_000, sleep_after_open=0)
    return cls(dev.tty_path, bitrate=500_000, sleep_after_open=0)


def wait_open(dev: SlcanDevice, timeout_s: float = 2.0) -> None:
    """Until the device has read the host's O (the pty hands bytes on asynchronously,
    and a frame sent before the channel is open is lost, as on a bus)."""
    deadline = time.monotonic() + timeout_s
    while not dev.is_open:
        assert time.monotonic() < deadline, "the host did not open the channel"
        assert dev.recv(0.01) is None


def recv_on(bus: can.BusABC, timeout_s: float = 2.0) -> can.Message:
    msg = bus.recv(timeout_s)
    assert msg is not None, f"no frame on {bus.channel_info} within {timeout_s} s"
    return msg


@pytest.fixture
def device() -> Iterator[SlcanDevice]:
    dev = SlcanDevice.open_pty()
    yield dev
    dev.shutdown()


frames = st.builds(
    can.Message,
    is_extended_id=st.booleans(),
    arbitration_id=st.integers(0, 0x7FF),
    data=st.binary(max_size=8),
)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.booleans(), frames, st.integers(0, 0x1FFFFFFF)), max_size=6))
def test_frames_cross_both_ways_with_standard_and_extended_ids(
    batch: list[tuple[bool, can.Message, int]],
) -> None:
    dev = SlcanDevice.open_pty()
    host = host_bus(dev)
    try:
        wait_open(dev)
        for to_device, msg, ext_id in batch:
            if msg.is_extended_id:
                msg.arbitration_id = ext_id
            sender, receiver = (host, dev) if to_device else (dev, host)
            sender.send(msg)
            got = recv_on(receiver)
            assert got.equals(msg, timestamp_delta=None, check_channel=False), (got, msg)
    finally:
        host.shutdown()
        dev.shutdown()


def test_the_host_setup_is_answered_as_an_adapter_does(device: SlcanDevice) -> None:
    host = host_bus(device)
    try:
        assert isinstance(host, can.interfaces.slcan.slcanBus)
        # python-can wrote C, S6, an empty line and O; V and N wait for their answers
        # while the device is served from another thread
        stop = threading.Event()
        server = threading.Thread(
            target=lambda: [device.recv(0.01) for _ in iter(stop.is_set, True)]
        )
        server.start()
        try:
            assert host.get_version(2.0) == (10, 13)
            assert host.get_serial_number(2.0) == "FA01"
        finally:
            stop.set()
            server.join()
        assert device.is_open and device.bitrate_code == "6"
        host.send(can.Message(arbitration_id=0x123, data=b"\x01"))
        assert recv_on(device).arbitration_id == 0x123
    finally:
        host.shutdown()
    assert device.recv(0.2) is None and not device.is_open  # the host's C closed it


def test_bad_bytes_are_refused_counted_and_logged_never_raised(
    device: SlcanDevice, caplog: pytest.LogCaptureFixture
) -> None:
    lines: list[tuple[str, bytes]] = []
    device.tap = lambda side, line: lines.append((side, line))
    host_fd = os.open(device.tty_path, os.O_RDWR | os.O_NOCTTY)
    try:
        garbage = [
            b"O",
            b"\xff\xfe",
            b"t12",
            b"t1232zz00",
            b"t80010",
            b"T1ABCDEF092",
            b"Q",
            b"x" * 40,
        ]
        with caplog.at_level(logging.WARNING, logger="services.scanner.sim.slcan_device"):
            os.write(host_fd, b"\r".join(garbage) + b"\rt1001AB\r")
            msg = recv_on(device)  # the good frame after the garbage still arrives
        assert msg.arbitration_id == 0x100 and msg.data == b"\xab"
        assert device.bad_lines == len(garbage) - 1  # O is good
        bad = [r for r in caplog.records if "bad line" in r.getMessage()]
        assert len(bad) == device.bad_lines and all("\n" not in r.getMessage() for r in bad)
        answers = [line for side, line in lines if side == "adapter"]
        assert answers == [b"\r", *[b"\a"] * device.bad_lines, b"z\r"]
    finally:
        os.close(host_fd)


def test_frames_are_not_passed_while_the_host_has_the_channel_closed(
    device: SlcanDevice,
) -> None:
    device.send(can.Message(arbitration_id=0x181, data=b"\x00"))  # nobody listening
    host = host_bus(device)
    try:
        host.send(can.Message(arbitration_id=0x100, data=b"\x01"))
        assert recv_on(device).arbitration_id == 0x100
        device.send(can.Message(arbitration_id=0x182, data=b"\x02"))
        assert recv_on(host).arbitration_id == 0x182  # not the 0x181 from before
        assert device.dropped == 1
    finally:
        host.shutdown()


class Rig:
    """The emulator on the adapter's end, the client on python-can's slcan (through
    :class:`SlcanHost`, as the scanner's ``can`` backend opens it); every SLCAN line
    on the wire recorded."""

    def __init__(self, faults: FaroFaults, clock: FakeClock | None = None) -> None:
        self.wire: list[tuple[str, bytes]] = []
        self.device = SlcanDevice.open_pty(tap=lambda side, line: self.wire.append((side, line)))
        now = clock or FakeClock()
        self.emulator = FaroEmulator(
            self.device,
            now=now,
            scan_duration_s=lambda _p: 10.0,
            status_period_s=0.02,
            faults=faults,
            inclination_deg=lambda: (1.234, -0.5),
        )
        self.device.bus_off = self.emulator.bus_off
        self.host = SlcanHost(
            self.device.tty_path, bitrate=500_000, sleep_after_open=0, status_poll_s=0.05
        )
        self.emulator.start()
        kw = {"ack_timeout_s": 0.2, "stuck_timeout_s": 100.0, "status_timeout_s": 100.0}
        self.client = ScannerClient(self.host, now=now, **kw)  # type: ignore[arg-type]

    def close(self) -> None:
        self.emulator.stop()
        self.host.shutdown()
        self.device.shutdown()

    def frames(self) -> list[tuple[str, int, bytes]]:
        """The CAN frames on the wire, parsed from the SLCAN lines here."""
        out = []
        for side, line in self.wire:
            line = line.rstrip(b"\r")
            if line[:1] in (b"t", b"T"):
                n = 3 if line[:1] == b"t" else 8
                size = int(line[1 + n : 2 + n])
                data = bytes.fromhex(line[2 + n : 2 + n + 2 * size].decode())
                out.append((side, int(line[1 : 1 + n], 16), data))
        return out


def test_every_frame_on_the_wire_decodes_with_the_dbc_through_cantools() -> None:
    clock = FakeClock()
    rig = Rig(FaroFaults(lose_first_acks=1), clock)
    try:
        assert rig.client.start_scan(PROFILE, scan_id=7) == 7  # its first ACK lost: resent
        rig.client.pause()
        rig.client.resume()
        clock.set(10.0)
        st = until(rig.client, lambda s: s.state != ScanState.SCANNING)
        assert st.state == ScanState.DONE and st.inclinometer is not None
    finally:
        rig.close()
    db = cantools.database.load_file(str(DBC))
    assert isinstance(db, cantools.database.can.Database)
    seen: dict[str, list[dict[str, object]]] = {}
    for side, frame_id, data in rig.frames():
        message = db.get_message_by_frame_id(frame_id)
        assert ("host" if message.senders == ["Host"] else "adapter") == side, message.name
        seen.setdefault(message.name, []).append(message.decode(data))  # type: ignore[arg-type]
    initiates = seen["InitiateScanOperation"]
    assert len(initiates) == 2 and initiates[0] == {"ScanId": 7, "ResolutionIndex": 4, "Quality": 2}
    assert [a["Result"] for a in seen["Ack"]] == ["Ok"] * 3  # one Initiate ACK lost
    assert [p["Action"] for p in seen["RecordPause"]] == ["Pause", "Record"]
    assert seen["Inclinometer"] == [{"Pitch": 1.234, "Roll": -0.5, "ScanId": 7}]
    assert seen["Status"][-1] == {"State": "Done", "Progress": 100, "ErrorCode": 0, "ScanId": 7}


def test_bus_off_shows_on_the_wire_as_adapter_flags_and_refused_frames() -> None:
    clock = FakeClock()
    rig = Rig(FaroFaults(bus_off_for_s=5.0), clock)
    try:
        rig.client.start_scan(PROFILE, scan_id=1)  # acknowledged, then the node goes off
        until(rig.client, lambda _s: rig.host.state == can.BusState.ERROR)
        assert rig.host.flags == BUS_OFF_FLAGS
        assert "bus error" in rig.host.error()
        with pytest.raises(AckTimeout, match=r"sending failed: .*bus error"):
            rig.client.pause()
        rig.host.flags = 0  # as if the last poll found it well: the frame goes out, refused
        rig.host.send(can.Message(arbitration_id=0x101, data=b"\x01", is_extended_id=False))
        until(rig.client, lambda _s: rig.host.refused > 0)
        assert ("host", b"t101101") in rig.wire and rig.wire[-1] != ("adapter", b"z\r")
        clock.set(6.0)  # the node is back
        until(rig.client, lambda s: rig.host.state == can.BusState.ACTIVE and s.progress_pct >= 60)
        clock.set(10.0)
        assert until(rig.client, lambda s: s.state != ScanState.SCANNING).state == ScanState.DONE
    finally:
        rig.close()
    adapter_lines = [line for side, line in rig.wire if side == "adapter"]
    assert b"FA6\r" in adapter_lines and b"F00\r" in adapter_lines


class _GoneAdapter(can.BusABC):
    """A bus whose adapter went before it was closed (unplugged, its pty shut)."""

    def __init__(self) -> None:
        super().__init__(channel="gone")

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise can.CanOperationError("gone")

    def _recv_internal(self, timeout: float | None) -> tuple[None, bool]:
        return None, False

    def shutdown(self) -> None:
        super().shutdown()
        raise can.CanOperationError("Input/output error")


def test_a_device_whose_adapter_is_gone_closes_with_one_line(
    caplog: pytest.LogCaptureFixture,
) -> None:
    from common.service import Context
    from services.scanner.config import ScannerConfig
    from services.scanner.device import CanDevice

    ctx = Context("scanner", "test", None, None, logging.getLogger("t"), Path("."))  # type: ignore[arg-type]
    dev = CanDevice(ctx, ScannerConfig(backend="can", interface="virtual", channel="gone-adapter"))
    dev.bus.shutdown()
    dev.bus = _GoneAdapter()
    with caplog.at_level(logging.WARNING):
        dev.close()  # no traceback ends the service's stop
    assert [r.getMessage() for r in caplog.records] == [
        "scanner: CAN virtual channel 'gone-adapter' did not close cleanly: Input/output error"
    ]
