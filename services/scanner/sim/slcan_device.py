"""The adapter's end of an SLCAN serial link, as a python-can bus.

SLCAN (Lawicel's ASCII protocol, spoken by CANUSB, CANable and most USB-CAN sticks)
runs between a host and its adapter over a serial line; python-can's ``slcan``
interface is the host. :class:`SlcanDevice` plays the adapter with a CAN bus behind
it on which the code using this bus is the only other node: what the host transmits
(``t``/``T``/``r``/``R``) comes out of :meth:`recv`, and what is sent here reaches the
host as the same lines. Over a pseudo-terminal (:meth:`SlcanDevice.open_pty`) this is
a CAN bus between two processes where the kernel has no SocketCAN.

Answers (Lawicel's CANUSB command list, as python-can 4.6's ``slcan.py`` and the
CANable 2 firmware's ``slcan.c`` use it): CR (OK) or BELL (error) to ``Sn``/``sxxyy``
(only while the channel is closed), ``O``/``L``, ``C``, an empty line and ``Z0``;
``V`` -> ``V1013``, ``N`` -> ``NFA01``, ``F`` -> ``Fxx`` (status flags, cleared by
reading); ``z``/``Z`` to a transmit the adapter takes, BELL to one it does not. CAN FD,
timestamps and acceptance filters are not supported (BELL).

Bus-off of the node behind the adapter (``bus_off()`` true) shows on the wire as a
real adapter shows it when no node acknowledges its frames: transmits are refused
with BELL and never delivered, nothing is received, and ``F`` reports bus error,
error passive, error warning and a full transmit FIFO (``0xA6``).

Bad input from the host (not ASCII, an unknown command, a malformed frame, a line
with no CR) is answered with BELL, logged in one line and counted in
``bad_lines``; it never raises.
"""

from __future__ import annotations

import logging
import os
import select
import termios
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from pathlib import Path

import can

from services.scanner.sim.slcan_text import frame_line, is_hex, parse_frame

log = logging.getLogger(__name__)

# Lawicel status flags (the reply to F)
RX_FIFO_FULL, TX_FIFO_FULL, ERROR_WARNING, DATA_OVERRUN = 0x01, 0x02, 0x04, 0x08
ERROR_PASSIVE, ARBITRATION_LOST, BUS_ERROR = 0x20, 0x40, 0x80
BUS_OFF_FLAGS = TX_FIFO_FULL | ERROR_WARNING | ERROR_PASSIVE | BUS_ERROR

OK, BELL = b"\r", b"\a"
VERSION, SERIAL_NUMBER = b"V1013\r", b"NFA01\r"  # python-can parses V as two 2-digit numbers
BITRATE_CODES = "0123456789"  # S0 10k .. S8 1M, S9 83.3k (CANable)
_MAX_LINE = 32  # the longest classic line, T + 8 id + dlc + 16 data, with room to spare
_MAX_PENDING = 64 * 1024  # bytes for a host that stopped reading; beyond: frames dropped
_LOGGED_BAD = 10  # bad lines logged one by one, then every 100th


class SlcanDevice(can.BusABC):
    """See the module docstring. ``fd``: the adapter's end of the serial line (a pty
    master), which this bus owns and sets non-blocking; ``bus_off``: whether the node
    on the bus behind the adapter is bus-off now (any thread). Thread-safe; the
    host's commands are answered while someone calls :meth:`recv` (an emulator
    polls it continuously)."""

    def __init__(
        self,
        fd: int,
        *,
        channel: str = "slcan",
        bus_off: Callable[[], bool] = lambda: False,
        slave_fd: int | None = None,
        link: Path | None = None,
        tap: Callable[[str, bytes], None] | None = None,
    ) -> None:
        super().__init__(channel=channel)
        self.channel_info = f"SLCAN adapter end of {channel}"
        self.tty_path = channel  # what the host opens
        self.bus_off = bus_off
        self.tap = tap  # sees every line: ("host", line without CR) and ("adapter", line)
        self.is_open = False  # the host opened the CAN channel (O or L)
        self.listen_only = False
        self.bitrate_code = "6"  # 500 kbit/s until the host sets one, as adapters ship
        self.bad_lines = 0  # malformed input from the host
        self.dropped = 0  # frames the host could not take (not open, or not reading)
        self._fd, self._slave_fd, self._link = fd, slave_fd, link
        os.set_blocking(fd, False)
        self._flags = 0
        self._inbuf, self._outbuf = bytearray(), bytearray()
        self._discarding = False  # inside an over-long line, until its CR
        self._rx: deque[can.Message] = deque()
        self._lock = threading.RLock()
        self._overrun = False  # frames being dropped for a host that does not read

    @classmethod
    def open_pty(
        cls,
        link: Path | None = None,
        bus_off: Callable[[], bool] = lambda: False,
        tap: Callable[[str, bytes], None] | None = None,
    ) -> SlcanDevice:
        """A pseudo-terminal pair: this bus on the master; the host opens the slave's
        path (``channel``), or the symlink ``link`` to it (replaced if present,
        removed at shutdown)."""
        master, slave = os.openpty()
        # Raw until the host configures its end: no echo of our lines back to us, no
        # CR -> LF on the way. The slave stays open here so that the host may close and
        # reopen it without the master seeing a hang-up.
        tty.setraw(slave)
        path = os.ttyname(slave)
        if link is not None:
            link.parent.mkdir(parents=True, exist_ok=True)
            tmp = link.with_name(f".{link.name}.{os.getpid()}")
            tmp.unlink(missing_ok=True)
            os.symlink(path, tmp)
            os.replace(tmp, link)  # atomic: a host never finds the link half made
        return cls(master, channel=path, bus_off=bus_off, slave_fd=slave, link=link, tap=tap)

    # --- CAN side ---

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Pass ``msg`` to the host. Lost, as on a bus, while the host has the channel
        closed or the node is bus-off; raises ``can.CanOperationError`` for CAN FD."""
        if msg.is_fd:
            raise can.CanOperationError("CAN FD is not supported on this SLCAN link")
        with self._lock:
            # the host's pending commands first: it may just have opened the channel
            self._take(self._read())
            if self.bus_off():
                self._flags |= BUS_OFF_FLAGS
                return
            if not self.is_open:
                self.dropped += 1
                return
            self._write(frame_line(msg), frame=True)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            with self._lock:
                self._flush()
                if self._rx:
                    return self._rx.popleft(), False
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            readable, _, _ = select.select([self._fd], [], [], wait)
            if readable:
                self._take(self._read())
            elif deadline is not None and time.monotonic() >= deadline:
                return None, False

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        super().shutdown()
        link = self._link
        if link is not None and link.is_symlink() and os.readlink(link) == self.tty_path:
            link.unlink()  # only ours: a newer emulator may have taken the path over
        for fd in (self._fd, self._slave_fd):
            if fd is not None:
                os.close(fd)

    # --- serial side ---

    def _read(self) -> bytes:
        try:
            return os.read(self._fd, 4096)
        except (BlockingIOError, InterruptedError):
            return b""

    def _write(self, data: bytes, frame: bool = False) -> None:
        if self.tap is not None:
            self.tap("adapter", data)
        if frame and len(self._outbuf) > _MAX_PENDING:
            # the host stopped reading: its adapter's receive FIFO overflows
            if not self._overrun:
                log.warning("SLCAN: the host is not reading; frames dropped until it does")
            self._overrun = True
            self.dropped += 1
            self._flags |= DATA_OVERRUN | RX_FIFO_FULL
            return
        self._outbuf += data
        self._overrun = False
        self._flush()

    def _flush(self) -> None:
        while self._outbuf:
            try:
                n = os.write(self._fd, self._outbuf)
            except (BlockingIOError, InterruptedError):
                return
            del self._outbuf[:n]

    def _take(self, data: bytes) -> None:
        with self._lock:
            self._inbuf += data
            while (end := self._inbuf.find(b"\r")) >= 0:
                line = bytes(self._inbuf[:end]).strip(b"\n")  # tolerate CR LF from a terminal
                del self._inbuf[: end + 1]
                if self._discarding:
                    self._discarding = False
                    continue
                self._line(line)
            if len(self._inbuf) > _MAX_LINE:
                self._bad(bytes(self._inbuf), f"no CR within {_MAX_LINE} bytes")
                self._inbuf.clear()
                self._discarding = True

    def _bad(self, line: bytes, why: str) -> None:
        self.bad_lines += 1
        if self.bad_lines <= _LOGGED_BAD or self.bad_lines % 100 == 0:
            log.warning(
                "SLCAN: bad line from host %r: %s (%d so far)", line[:40], why, self.bad_lines
            )
        self._write(BELL)

    def _line(self, raw: bytes) -> None:
        if self.tap is not None:
            self.tap("host", raw)
        try:
            line = raw.decode("ascii")
        except UnicodeDecodeError:
            self._bad(raw, "not ASCII")
            return
        if not line:
            self._write(OK)  # python-can sends an empty data-bitrate command
            return
        cmd, arg = line[0], line[1:]
        if cmd in "tTrR":
            self._transmit(raw, line)
        elif cmd == "S" and len(arg) == 1 and arg in BITRATE_CODES:
            self._config(lambda: setattr(self, "bitrate_code", arg))
        elif cmd == "s" and len(arg) in (4, 6) and is_hex(arg):
            self._config(lambda: None)  # register timing: accepted, the link has no bit time
        elif cmd in "OL" and not arg:
            self._open(listen_only=cmd == "L")
        elif line == "C":
            self._close()
        elif line == "V":
            self._write(VERSION)
        elif line == "N":
            self._write(SERIAL_NUMBER)
        elif line == "F":
            self._status()
        elif line == "Z0":
            self._write(OK)
        else:
            self._bad(raw, "unknown or unsupported command")

    def _config(self, apply: Callable[[], None]) -> None:
        if self.is_open:
            self._write(BELL)  # Lawicel: setup only while the channel is closed
            return
        apply()
        self._write(OK)

    def _open(self, listen_only: bool) -> None:
        if self.is_open:
            self._write(BELL)
            return
        self.is_open, self.listen_only, self._flags = True, listen_only, 0
        self._write(OK)

    def _close(self) -> None:
        self.is_open = False
        # Closing drops what the host has not read yet, so a host that reopens (python-
        # can sends C first) never reads frames from before; the slave's queue is
        # flushed from here because we hold that end open.
        self._outbuf.clear()
        if self._slave_fd is not None:
            termios.tcflush(self._slave_fd, termios.TCIFLUSH)
        self._write(OK)

    def _status(self) -> None:
        if not self.is_open:
            self._write(BELL)
            return
        if self.bus_off():
            self._flags |= BUS_OFF_FLAGS
        self._write(f"F{self._flags:02X}\r".encode())
        self._flags = 0  # read clears them; a lasting condition raises them again

    def _transmit(self, raw: bytes, line: str) -> None:
        frame = parse_frame(line, self.tty_path)
        if isinstance(frame, str):
            self._bad(raw, frame)
            return
        if not self.is_open or self.listen_only:
            self._write(BELL)
            return
        if self.bus_off():
            # Nobody acknowledges it: the adapter's transmit FIFO stays full.
            self._flags |= BUS_OFF_FLAGS
            self._write(BELL)
            return
        self._write(b"Z\r" if frame.is_extended_id else b"z\r")
        self._rx.append(frame)
