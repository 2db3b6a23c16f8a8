"""Simulated Reach M2 receivers on real wires (``services.gnss.sim.reach``): the TCP
byte stream checked by pynmeagps, and the gnss service's hardware backends
(``nmea-tcp``, ``nmea-serial``) reading it through a dropped link and line noise."""

from __future__ import annotations

import math
import signal
import socket
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pynmeagps
import pytest

from common import keys
from common.client import wait_alive
from common.clock import NS
from common.field_geojson import load_frame
from common.messages.gnss import NavSatFix
from common.messages.sim import SimAntennas
from common.transport import Bus
from tests.conftest import Procs, free_port, record

P1, P2 = (10.0, 5.0, 1.1), (10.95, 5.0, 1.1)


class Truth:
    """A stand-in simulator: antenna truth at 10 Hz of sim time, paced at 10 Hz of
    wall time (pacing the input, not synchronising the test) from a thread."""

    def __init__(self, bus: Bus) -> None:
        self.pub = bus.publisher(keys.SIM_ANTENNAS)
        self.stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)

    def start(self) -> None:
        assert self.pub.wait_matched(timeout=10)
        self._t.start()

    def _run(self) -> None:
        k = 0
        while not self.stop.wait(0.1):
            self.pub.put(SimAntennas(stamp_ns=k * NS // 10, p1=P1, p2=P2))
            k += 1

    def close(self) -> None:
        self.stop.set()
        if self._t.is_alive():
            self._t.join()


@pytest.fixture
def truth(client_bus: Bus) -> Iterator[Truth]:
    t = Truth(client_bus)
    yield t
    t.close()


def reach_sim(
    procs: Procs, endpoint: str, log: Path, outputs: str, *extra: str
) -> subprocess.Popen[bytes]:
    return procs.service(
        "services.gnss.sim.reach",
        endpoint,
        *("--field", "engr", "--set", f"outputs={outputs}", *extra),
        log=log,
    )


def gnss(procs: Procs, endpoint: str, log: Path, backend: str, antennas: str) -> None:
    procs.service(
        "services.gnss",
        endpoint,
        *("--field", "engr", "--set", f"backend={backend}", "--set", f"antennas={antennas}"),
        log=log,
    )


def test_tcp_stream_is_a_reach_m2_at_10_hz_near_truth(
    procs: Procs, router_endpoint: str, client_bus: Bus, truth: Truth, tmp_path: Path
) -> None:
    port = free_port()
    reach_sim(procs, router_endpoint, tmp_path / "reach.log", f"[{{id = 1, tcp_port = {port}}}]")
    assert wait_alive(client_bus.session, {"reach-sim"}, timeout=20)
    truth.start()
    msgs: list[pynmeagps.NMEAMessage] = []
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        # pynmeagps reads the socket itself and raises on any bad checksum or framing
        reader = pynmeagps.NMEAReader(
            sock.makefile("rb"), validate=pynmeagps.VALCKSUM, quitonerror=pynmeagps.ERR_RAISE
        )
        while sum(m.msgID == "GGA" for m in msgs) < 20:
            raw, msg = reader.read()
            assert raw is not None and msg is not None
            msgs.append(msg)
    # a client that connects mid-stream starts at an epoch boundary
    assert msgs[0].identity == "GNRMC", msgs[0]
    ids = [m.identity for m in msgs]
    assert ids[: 4 * 19] == ["GNRMC", "GNGGA", "GNGST", "GNVTG"] * 19, ids
    ggas = [m for m in msgs if m.msgID == "GGA"]
    gsts = [m for m in msgs if m.msgID == "GST"]
    times = [
        g.time.hour * 3600 + g.time.minute * 60 + g.time.second + g.time.microsecond / 1e6
        for g in ggas
    ]
    assert np.allclose(np.diff(times), 0.1, atol=1e-3), times  # 10 Hz
    frame = load_frame("engr")
    for g, s in zip(ggas, gsts, strict=False):
        x, y, z = frame.wgs84_to_field(g.lat, g.lon, g.alt + g.sep)
        err = np.array([float(x) - P1[0], float(y) - P1[1], float(z) - P1[2]])
        sd = max(s.stdLat, s.stdLong)
        # within 5 sigma of the receiver's own estimate (the RTK model's noise)
        assert math.hypot(err[0], err[1]) < 5 * math.sqrt(2) * sd, (err, sd, g.quality)
        assert abs(err[2]) < 5 * s.stdAlt, (err, s.stdAlt)


def fix_gap_s(fixes: list[NavSatFix]) -> float:
    stamps = np.array([f.stamp_ns for f in fixes]) / NS
    return float(np.diff(stamps).max())


def test_nmea_tcp_backend_is_back_within_a_second_of_a_dropped_link(
    procs: Procs, router_endpoint: str, client_bus: Bus, truth: Truth, tmp_path: Path
) -> None:
    ports = free_port(), free_port()
    reach_sim(
        procs,
        router_endpoint,
        tmp_path / "reach.log",
        f"[{{id = 1, tcp_port = {ports[0]}}}, {{id = 2, tcp_port = {ports[1]}}}]",
        *("--set", "faults.drop_links_at_s=[3.0]"),
    )
    assert wait_alive(client_bus.session, {"reach-sim"}, timeout=20)
    fixes = record(client_bus, keys.GNSS_FIX.at(antenna=1))
    health = client_bus.latest(keys.HEALTH.at(service="gnss"))
    ants = ", ".join(
        f"{{id = {i + 1}, host = '127.0.0.1', tcp_port = {p}}}" for i, p in enumerate(ports)
    )
    gnss(procs, router_endpoint, tmp_path / "gnss.log", "nmea-tcp", f"[{ants}]")
    assert wait_alive(client_bus.session, {"gnss"}, timeout=20)
    truth.start()
    assert fixes.until(lambda fs: len(fs) >= 5, timeout=10), "no fixes over TCP"
    h = health.wait_for(lambda h: h.counters.get("antenna1_link_outages", 0) >= 1, timeout=10)
    assert h is not None, "the link was not dropped"
    n = len(fixes)
    assert fixes.until(lambda fs: len(fs) >= n + 10, timeout=5), "no fixes after the drop"
    gap = fix_gap_s(list(fixes))
    assert gap < 1.0, f"fixes stopped for {gap:.2f} s"
    log = (tmp_path / "gnss.log").read_text().splitlines()
    lost = [ln for ln in log if "antenna 1: link" in ln and "lost" in ln]
    back = [ln for ln in log if "antenna 1: link" in ln and "back after" in ln]
    assert len(lost) == 1 and len(back) == 1, log
    print(f"largest gap between fixes {gap:.3f} s; {back[0]}")


def test_nmea_serial_backend_on_the_pty_survives_line_noise(
    procs: Procs, router_endpoint: str, client_bus: Bus, truth: Truth, tmp_path: Path
) -> None:
    ptys = tmp_path / "hil" / "gnss1.pty", tmp_path / "hil" / "gnss2.pty"
    sim = reach_sim(
        procs,
        router_endpoint,
        tmp_path / "reach.log",
        f"[{{id = 1, pty = '{ptys[0]}'}}, {{id = 2, pty = '{ptys[1]}'}}]",
    )
    assert wait_alive(client_bus.session, {"reach-sim"}, timeout=20)
    fixes = record(client_bus, keys.GNSS_FIX.at(antenna=1))
    headings = record(client_bus, keys.GNSS_HEADING)
    health = client_bus.latest(keys.HEALTH.at(service="gnss"))
    ants = ", ".join(f"{{id = {i + 1}, port = '{p}'}}" for i, p in enumerate(ptys))
    gnss(procs, router_endpoint, tmp_path / "gnss.log", "nmea-serial", f"[{ants}]")
    assert wait_alive(client_bus.session, {"gnss"}, timeout=20)
    truth.start()
    assert fixes.until(lambda fs: len(fs) >= 5, timeout=10), "no fixes over the pty"
    assert headings.until(bool, timeout=5), "no heading from the two serial receivers"
    sim.send_signal(signal.SIGUSR2)  # garbage into both serial lines
    h = health.wait_for(
        lambda h: h.counters.get("antenna1_garbage_bytes", 0) > 0 and h.decode_errors >= 2,
        timeout=10,
    )
    assert h is not None, f"line noise was not counted: {health.get()}"
    n = len(fixes)
    assert fixes.until(lambda fs: len(fs) >= n + 10, timeout=5), "fixes stopped after the noise"
    assert "Traceback" not in (tmp_path / "gnss.log").read_text()
