"""Receivers: where NMEA bytes come from. Every backend yields raw bytes, so a
simulated receiver goes through the same line splitter and parser as a real one.

``BACKENDS`` maps the config's ``backend`` name to the class, imported lazily.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import queue
import socket
import threading
from typing import Protocol

import msgspec
import numpy as np

from common import keys
from common.clock import NS
from common.geo import FieldFrame
from common.messages.sim import SimAntennas
from common.transport import Bus
from services.gnss.config import AntennaConfig, GnssConfig
from services.gnss.nmea import FixQuality, Gga, Gst
from services.gnss.nmea_format import format_gga, format_gst
from services.gnss.rtk_model import STATES, RtkErrorModel, RtkSample

log = logging.getLogger(__name__)


class Receiver(Protocol):
    antenna: int

    def read(self, stop: threading.Event) -> bytes:
        """Bytes received since the last call; ``b""`` after ~0.5 s without any."""
        ...

    def close(self) -> None: ...


BACKENDS = {
    "nmea-serial": "services.gnss.receiver:SerialNmea",
    "nmea-tcp": "services.gnss.receiver:TcpNmea",
    "sim": "services.gnss.receiver:SimReceiver",
}


def open_receiver(cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame) -> Receiver:
    module, _, name = BACKENDS[cfg.backend].partition(":")
    cls = getattr(importlib.import_module(module), name)
    r: Receiver = cls(cfg, antenna, bus, frame)
    return r


class SerialNmea:
    def __init__(self, cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame):
        import serial  # pyserial: only the serial backend needs it

        self.antenna = antenna.id
        self._ser = serial.Serial(antenna.port, antenna.baud, timeout=0.5)

    def read(self, stop: threading.Event) -> bytes:
        data: bytes = self._ser.read(max(1, self._ser.in_waiting))
        return data

    def close(self) -> None:
        self._ser.close()


class TcpNmea:
    """NMEA over TCP; reconnects (every 2 s) after the receiver drops the link."""

    def __init__(self, cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame):
        self.antenna = antenna.id
        self._addr = (antenna.host, antenna.tcp_port)
        self._sock: socket.socket | None = None
        self._warned = False

    def read(self, stop: threading.Event) -> bytes:
        if self._sock is None:
            try:
                self._sock = socket.create_connection(self._addr, timeout=2.0)
                self._sock.settimeout(0.5)
                log.info("antenna %d: connected to %s:%d", self.antenna, *self._addr)
                self._warned = False
            except OSError as exc:
                if not self._warned:
                    log.warning(
                        "antenna %d: cannot reach %s:%d: %s", self.antenna, *self._addr, exc
                    )
                    self._warned = True
                stop.wait(2.0)
                return b""
        try:
            data = self._sock.recv(4096)
        except TimeoutError:
            return b""
        except OSError as exc:
            data, reason = b"", str(exc)
        else:
            reason = "closed by the receiver"
        if not data:
            log.warning("antenna %d: link lost (%s); reconnecting", self.antenna, reason)
            self._sock.close()
            self._sock = None
        return data

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()


def receiver_output(
    frame: FieldFrame, truth: tuple[float, float, float], sample: RtkSample, tod: float
) -> str:
    """What a Reach M2 sends for one epoch: GST (its error estimate) then GGA, for an
    antenna truly at ``truth`` (field frame, m) with the RTK model's ``sample`` of
    error; ``tod`` seconds of the UTC day. No fix: a GGA without position."""
    if sample.error_enu_m is None or sample.sigma_enu_m is None:
        return format_gga(
            Gga(time_s=tod, lat_deg=None, lon_deg=None, alt_msl_m=None, quality=sample.state)
        )
    err, sig = sample.error_enu_m, sample.sigma_enu_m
    e, n = frame.field_to_map(truth[0], truth[1])
    lat, lon, h = frame.map_to_wgs84(e + err[0], n + err[1], truth[2] + err[2])
    gst = Gst(
        time_s=tod,
        rms_m=float(np.linalg.norm(sig)),
        std_major_m=float(sig[0]),
        std_minor_m=float(sig[1]),
        orient_deg=0.0,
        std_lat_m=float(sig[1]),
        std_lon_m=float(sig[0]),
        std_alt_m=float(sig[2]),
    )
    gga = Gga(
        time_s=tod,
        lat_deg=float(lat),
        lon_deg=float(lon),
        alt_msl_m=float(h),
        geoid_sep_m=0.0,
        quality=sample.state,
        num_sats=18,
        hdop=0.6,
        diff_age_s=1.0,
    )
    return format_gst(gst) + format_gga(gga)


class SimReceiver:
    """A simulated Reach M2: antenna truth from the simulator, errors from the RTK
    model, out as GST + GGA sentences at the simulator's antenna rate (10 Hz).

    It honours the faults the simulator injects (fields of :class:`SimAntennas`):
    an outage sends nothing; a forced float reports RTK float (quality 5) with the
    float noise of a second RTK model locked in FLOAT; a multipath offset is added
    to the reported position with the quality unchanged. Both models step every
    epoch whatever the faults, on their own generators, so the receiver's noise
    outside a fault is the same with or without it."""

    def __init__(self, cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame):
        self.antenna = antenna.id
        self._frame = frame
        self._model = RtkErrorModel(cfg.rtk, np.random.default_rng([cfg.seed, antenna.id]))
        no_jumps = [[0.0] * len(STATES) for _ in STATES]
        locked = msgspec.structs.replace(
            cfg.rtk, initial_state=FixQuality.FLOAT, rates_per_s=no_jumps
        )
        self._float = RtkErrorModel(locked, np.random.default_rng([cfg.seed, antenna.id, 5]))
        self._queue: queue.Queue[bytes] = queue.Queue(maxsize=100)
        self._last_ns: int | None = None
        bus.subscribe(keys.SIM_ANTENNAS, self._on_truth)

    def epoch(self, msg: SimAntennas) -> str:
        """The sentences for one simulator epoch (``""`` during an outage). Steps the
        error models by the time since the previous epoch (sim time)."""
        dt = 0.1 if self._last_ns is None else max(1e-3, (msg.stamp_ns - self._last_ns) / NS)
        self._last_ns = msg.stamp_ns
        sample = self._model.step(dt)
        floating = self._float.step(dt)
        one = self.antenna == 1
        if msg.outage1 if one else msg.outage2:
            return ""
        if msg.force_float1 if one else msg.force_float2:
            sample = floating
        east, north = msg.offset1 if one else msg.offset2
        if sample.error_enu_m is not None and (east or north):
            e, n, u = sample.error_enu_m
            sample = msgspec.structs.replace(sample, error_enu_m=(e + east, n + north, u))
        p = msg.p1 if one else msg.p2
        return receiver_output(self._frame, p, sample, (msg.stamp_ns / NS) % 86400.0)

    def _on_truth(self, msg: SimAntennas) -> None:
        text = self.epoch(msg)
        if text:
            self._push(text)

    def _push(self, text: str) -> None:
        # nobody reading: drop, as a serial port would overrun
        with contextlib.suppress(queue.Full):
            self._queue.put_nowait(text.encode("ascii"))

    def read(self, stop: threading.Event) -> bytes:
        try:
            return self._queue.get(timeout=0.5)
        except queue.Empty:
            return b""

    def close(self) -> None:
        pass
