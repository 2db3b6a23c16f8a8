"""The wires a simulated Reach M2 talks on: a TCP server with any number of clients,
and a serial line made of a pseudo-terminal. Both take whole epochs of NMEA bytes
from one writer thread and never block it."""

from __future__ import annotations

import contextlib
import fcntl
import logging
import os
import socket
import struct
import termios
import threading
import tty
from pathlib import Path

log = logging.getLogger(__name__)


class TcpFanout:
    """A listening TCP server; every client gets the byte stream from when it
    connected (like a Reach's "TCP server" output). A client that stops reading
    until its socket buffer is full is dropped rather than stalling the others."""

    def __init__(self, host: str, port: int, name: str) -> None:
        self.name = name
        self._srv = socket.create_server((host, port))
        self._srv.settimeout(0.5)  # so the accept loop sees stop
        self.host, self.port = self._srv.getsockname()[:2]
        self._lock = threading.Condition()
        self._clients: list[tuple[socket.socket, str]] = []
        self.accepted = 0

    @property
    def clients(self) -> int:
        with self._lock:
            return len(self._clients)

    def wait_accepted(self, n: int, timeout: float) -> bool:
        """Whether ``n`` clients in all have connected within ``timeout`` seconds."""
        with self._lock:
            return self._lock.wait_for(lambda: self.accepted >= n, timeout)

    def serve(self, stop: threading.Event) -> None:
        """Accept clients until ``stop`` (blocking: run it in a thread)."""
        while not stop.is_set():
            try:
                conn, peer = self._srv.accept()
            except TimeoutError:
                continue
            except OSError:
                return  # closed
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            who = f"{peer[0]}:{peer[1]}"
            with self._lock:
                self._clients.append((conn, who))
                self.accepted += 1
                self._lock.notify_all()
            log.info("%s: client %s connected", self.name, who)

    def send(self, data: bytes) -> None:
        with self._lock:
            keep = []
            for conn, who in self._clients:
                try:
                    if conn.send(data) == len(data):
                        keep.append((conn, who))
                        continue
                    reason = "not reading (send buffer full)"
                except BlockingIOError:
                    reason = "not reading (send buffer full)"
                except OSError as exc:
                    reason = str(exc) or type(exc).__name__
                conn.close()
                log.info("%s: client %s gone (%s)", self.name, who, reason)
            self._clients = keep

    def drop_all(self) -> int:
        """Disconnect every client (the server keeps listening); how many there were."""
        with self._lock:
            gone, self._clients = self._clients, []
        for conn, _ in gone:
            with contextlib.suppress(OSError):
                conn.shutdown(socket.SHUT_RDWR)
            conn.close()
        return len(gone)

    def close(self) -> None:
        self._srv.close()
        self.drop_all()


class PtyLine:
    """A serial line: a pseudo-terminal in raw mode whose far end (the slave) is
    symlinked at ``link``, for a serial reader (pyserial) to open as its port.

    Like a wire, it keeps no backlog: bytes nobody read within about half a second
    (``MAX_BACKLOG`` bytes) are discarded, so a reader that opens the port late
    starts at the present, not at what was sent before it came."""

    MAX_BACKLOG = 2048

    def __init__(self, link: Path) -> None:
        self.link = link
        self._master, self._slave = os.openpty()
        # raw: no echo back into the master, no CR/LF translation: bytes pass as sent
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        link.parent.mkdir(parents=True, exist_ok=True)
        # replace a stale link from an earlier run in one step
        tmp = link.with_name(f".{link.name}.{os.getpid()}")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        os.symlink(self.device, tmp)
        os.replace(tmp, link)
        self.overruns = 0

    def _pending(self) -> int:
        raw = fcntl.ioctl(self._slave, termios.FIONREAD, b"\0\0\0\0")
        n: int = struct.unpack("i", raw)[0]
        return n

    def send(self, data: bytes) -> None:
        if self._pending() > self.MAX_BACKLOG:
            termios.tcflush(self._slave, termios.TCIFLUSH)
        try:
            os.write(self._master, data)
        except BlockingIOError:
            self.overruns += 1

    def close(self) -> None:
        # remove the link only if it is still ours (a newer run may own it now)
        with contextlib.suppress(OSError):
            if os.readlink(self.link) == self.device:
                self.link.unlink()
        os.close(self._master)
        os.close(self._slave)
