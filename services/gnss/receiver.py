"""Receivers: where NMEA bytes come from. Every backend yields raw bytes, so a
simulated receiver goes through the same line splitter and parser as a real one.
A link that drops (TCP, serial) is reopened by the backend itself within a second.

``BACKENDS`` maps the config's ``backend`` name to the class, imported lazily.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import queue
import socket
import threading
import time
from collections.abc import Callable
from typing import Protocol

from common import keys
from common.geo import FieldFrame
from common.messages.sim import SimAntennas
from common.transport import Bus
from services.gnss.config import AntennaConfig, GnssConfig
from services.gnss.reach import ReachM2
from services.gnss.reach import receiver_output as receiver_output  # moved; bench imports it

log = logging.getLogger(__name__)


class Receiver(Protocol):
    antenna: int

    def read(self, stop: threading.Event) -> bytes:
        """Bytes received since the last call; ``b""`` after ~0.5 s without any."""
        ...

    def deliver(self, sink: Callable[[bytes], None]) -> bool:
        """Hand what arrives to ``sink`` as it arrives, in the receiver's own thread,
        instead of to :meth:`read`; False when this receiver can only be read."""
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


class _Link:
    """A receiver link that can drop (a TCP socket, a serial device): reopened at
    once after a loss, then with a short capped backoff, so fixes are back within a
    second of the receiver coming back. One log line per outage, not per attempt;
    ``outages`` counts them (in the service's health counters)."""

    FIRST_RETRY_S = 0.05
    MAX_RETRY_S = 0.5

    def __init__(self, antenna: int, where: str, bus: Bus) -> None:
        self.antenna = antenna
        self.where = where
        self.outages = 0
        self._up = False
        self._attempts = 0
        self._down_since: float | None = None
        bus.report(f"antenna{antenna}_link_outages", lambda: self.outages)

    def _open(self) -> None:
        raise NotImplementedError

    def _recv(self) -> bytes:
        """Bytes now; ``b""`` after a quiet ~0.5 s; raises OSError when the link is gone."""
        raise NotImplementedError

    def _shut(self) -> None:
        raise NotImplementedError

    def read(self, stop: threading.Event) -> bytes:
        if not self._up:
            try:
                self._open()
            except OSError as exc:
                if self._down_since is None:  # never up yet: say so once
                    self._down_since = time.monotonic()
                    log.warning("antenna %d: cannot reach %s (%s); retrying", *self._who(), exc)
                # the first retry after a loss is immediate (a receiver that only
                # dropped the connection is listening again at once), then doubling
                delay = min(self.MAX_RETRY_S, self.FIRST_RETRY_S * 2 ** min(self._attempts, 8))
                self._attempts += 1
                stop.wait(delay)
                return b""
            self._up_again()
        try:
            return self._recv()
        except OSError as exc:
            self._lost(str(exc) or type(exc).__name__)
            return b""

    def _who(self) -> tuple[int, str]:
        return self.antenna, self.where

    def _up_again(self) -> None:
        self._up = True
        if self._down_since is None or not self.outages:
            log.info("antenna %d: connected to %s", *self._who())
        else:
            log.info(
                "antenna %d: link to %s back after %.2f s (%d retries)",
                *self._who(),
                time.monotonic() - self._down_since,
                self._attempts,
            )
        self._down_since, self._attempts = None, 0

    def _lost(self, reason: str) -> None:
        self._up = False
        self.outages += 1
        self._down_since = time.monotonic()
        with contextlib.suppress(OSError):
            self._shut()
        log.warning("antenna %d: link to %s lost (%s); reconnecting", *self._who(), reason)

    def deliver(self, sink: Callable[[bytes], None]) -> bool:
        return False  # a port or a socket is read

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._shut()


class SerialNmea(_Link):
    """NMEA over a serial port (or a pseudo-terminal); reopened if it goes away."""

    def __init__(self, cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame):
        import serial  # pyserial: only the serial backend needs it

        super().__init__(antenna.id, antenna.port, bus)
        # opened by read(), so a port missing at start is retried like a lost one
        self._ser = serial.Serial(None, antenna.baud, timeout=0.5)
        self._ser.port = antenna.port

    def _open(self) -> None:
        self._ser.open()  # pyserial's SerialException is an OSError

    def _recv(self) -> bytes:
        data: bytes = self._ser.read(max(1, self._ser.in_waiting))
        return data

    def _shut(self) -> None:
        self._ser.close()


class TcpNmea(_Link):
    """NMEA over TCP (a Reach M2 "TCP server" position output)."""

    def __init__(self, cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame):
        super().__init__(antenna.id, f"{antenna.host}:{antenna.tcp_port}", bus)
        self._addr = (antenna.host, antenna.tcp_port)
        self._sock: socket.socket | None = None

    def _open(self) -> None:
        self._sock = socket.create_connection(self._addr, timeout=1.0)
        self._sock.settimeout(0.5)

    def _recv(self) -> bytes:
        assert self._sock is not None
        try:
            data = self._sock.recv(4096)
        except TimeoutError:
            return b""
        if not data:
            raise ConnectionError("closed by the receiver")
        return data

    def _shut(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


class SimReceiver:
    """A simulated Reach M2 on the Zenoh wire: antenna truth from the simulator
    (``sim/device/antennas``), out as the NMEA text of :class:`ReachM2` (errors from
    the RTK model, the simulator's faults honoured) at the simulator's antenna rate."""

    def __init__(self, cfg: GnssConfig, antenna: AntennaConfig, bus: Bus, frame: FieldFrame):
        self.antenna = antenna.id
        self._reach = ReachM2(cfg.rtk, cfg.seed, antenna.id, frame)
        self._queue: queue.Queue[bytes] = queue.Queue(maxsize=100)
        # set (deliver): each epoch's text goes straight to it, in the subscriber's
        # thread, rather than to a reader
        self._sink: Callable[[bytes], None] | None = None
        bus.subscribe(keys.SIM_ANTENNAS, self._on_truth)

    def epoch(self, msg: SimAntennas) -> str:
        """The sentences for one simulator epoch (``""`` during an outage)."""
        return self._reach.epoch(msg)

    def _on_truth(self, msg: SimAntennas) -> None:
        text = self.epoch(msg)
        if text:
            self._push(text)

    def _push(self, text: str) -> None:
        if self._sink is not None:
            self._sink(text.encode("ascii"))
            return
        # nobody reading: drop, as a serial port would overrun
        with contextlib.suppress(queue.Full):
            self._queue.put_nowait(text.encode("ascii"))

    def deliver(self, sink: Callable[[bytes], None]) -> bool:
        """Each epoch's text to ``sink`` as the simulator's antenna truth comes in (in
        lockstep at its step), not through a reader's queue."""
        self._sink = sink
        return True

    def read(self, stop: threading.Event) -> bytes:
        try:
            return self._queue.get(timeout=0.5)
        except queue.Empty:
            return b""

    def close(self) -> None:
        pass
