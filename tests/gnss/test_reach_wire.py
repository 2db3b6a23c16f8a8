"""The simulated Reach's wires (TCP server, pseudo-terminal) read by the gnss
service's own hardware backends, in one process: quick reconnects, no backlog."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import cast

import pytest

from common.geo import FieldFrame
from common.transport import Bus
from services.gnss.config import AntennaConfig, GnssConfig
from services.gnss.receiver import SerialNmea, TcpNmea
from services.gnss.sim.wire import PtyLine, TcpFanout

FRAME = FieldFrame(33.717028, -83.308083, 200.0, 90.0)
LINE = b"$GNVTG,,T,,M,0.0000,N,0.0000,K,R*2E\r\n"


class FakeBus:
    def __init__(self) -> None:
        self.counts: dict[str, Callable[[], int]] = {}

    def report(self, name: str, read: Callable[[], int]) -> None:
        self.counts[name] = read


class Feeder:
    """Sends ``LINE`` to a wire at 50 Hz from a thread, as an epoch stream would."""

    def __init__(self, send: Callable[[bytes], None]) -> None:
        self.stop = threading.Event()
        self._t = threading.Thread(target=self._run, args=(send,), daemon=True)
        self._t.start()

    def _run(self, send: Callable[[bytes], None]) -> None:
        while not self.stop.wait(0.02):
            send(LINE)

    def close(self) -> None:
        self.stop.set()
        self._t.join()


def read_until(read: Callable[[threading.Event], bytes], want: bytes, timeout: float) -> bytes:
    got, stop, deadline = b"", threading.Event(), time.monotonic() + timeout
    while want not in got and time.monotonic() < deadline:
        got += read(stop)
    return got


@pytest.fixture
def server() -> Iterator[TcpFanout]:
    srv = TcpFanout("127.0.0.1", 0, "test TCP")
    stop = threading.Event()
    t = threading.Thread(target=srv.serve, args=(stop,), daemon=True)
    t.start()
    yield srv
    stop.set()
    srv.close()
    t.join()


def test_port_0_picks_a_free_port_and_every_client_gets_the_stream(server: TcpFanout) -> None:
    assert server.port > 0
    feed = Feeder(server.send)
    try:
        rxs = [
            TcpNmea(
                GnssConfig(backend="nmea-tcp"),
                AntennaConfig(id=1, host="127.0.0.1", tcp_port=server.port),
                cast(Bus, FakeBus()),
                FRAME,
            )
            for _ in range(2)
        ]
        for rx in rxs:
            assert LINE in read_until(rx.read, LINE, timeout=5)
        assert server.clients == 2
        for rx in rxs:
            rx.close()
    finally:
        feed.close()


def test_tcp_link_dropped_is_back_within_a_second_with_one_log_line_each_way(
    server: TcpFanout, caplog: pytest.LogCaptureFixture
) -> None:
    bus = FakeBus()
    rx = TcpNmea(
        GnssConfig(backend="nmea-tcp"),
        AntennaConfig(id=1, host="127.0.0.1", tcp_port=server.port),
        cast(Bus, bus),
        FRAME,
    )
    feed = Feeder(server.send)
    try:
        assert LINE in read_until(rx.read, LINE, timeout=5)
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="services.gnss.receiver"):
            assert server.drop_all() == 1
            dropped = time.monotonic()
            got = read_until(rx.read, LINE, timeout=5)
            back = time.monotonic() - dropped
        assert LINE in got and back < 1.0, back
        lost = [r for r in caplog.records if "lost" in r.getMessage()]
        again = [r for r in caplog.records if "back after" in r.getMessage()]
        assert len(lost) == 1 and len(again) == 1, caplog.text
        assert bus.counts["antenna1_link_outages"]() == 1
    finally:
        feed.close()
        rx.close()


def test_serial_backend_reads_the_pty_and_reopens_it(tmp_path: Path) -> None:
    link = tmp_path / "hil" / "gnss1.pty"
    line = PtyLine(link)
    rx = SerialNmea(
        GnssConfig(backend="nmea-serial"),
        AntennaConfig(id=1, port=str(link)),
        cast(Bus, FakeBus()),
        FRAME,
    )
    feed = Feeder(line.send)
    try:
        assert LINE in read_until(rx.read, LINE, timeout=5)
    finally:
        feed.close()
        rx.close()
        line.close()
    assert not link.exists()  # the simulator removes its link when it closes


def test_pty_keeps_no_backlog_for_a_late_reader(tmp_path: Path) -> None:
    line = PtyLine(tmp_path / "gnss2.pty")
    try:
        for k in range(1000):  # ~40 kB while nobody reads: a wire would lose it
            line.send(b"$OLD,%04d*00\r\n" % k)
        assert line._pending() <= PtyLine.MAX_BACKLOG + 20
        assert line.overruns == 0  # discarded, never blocked
    finally:
        line.close()
