"""Client of the FARO automation interface over a python-can bus (no Zenoh here).

Commands (:meth:`ScannerClient.start_scan`, ``pause``, ``resume``, ``stop``) send a
frame and block until its ACK, resending up to ``retries`` times; Status frames that
arrive meanwhile are tracked too. Between commands the owner calls :meth:`poll`
(or :meth:`wait_finished`) to keep the status current.

Guarantees: a scan is reported DONE only when the device says so for *this* scan id
at 100 %; a scan whose progress stops for ``stuck_timeout_s``, a device that goes
silent for ``status_timeout_s``, or one that drops to idle unasked, is reported as
ERROR with the reason. Errors stay until the next ``start_scan``.

Two clocks: ACK timeouts and :meth:`ScannerClient.poll` are bus waits, measured in
wall time (the device answers commands in real time, whatever a sim clock does).
Scan-level timeouts (stuck, silent, :meth:`ScannerClient.wait_finished`) follow the
injected clock ``now`` (seconds), because a scan's duration follows the clock that
drives the scanner, which a sim may run fast, slow or paused; ``wait_finished`` on
a paused clock returns only when the scan finishes. Not thread-safe: one thread
owns the client.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import can
import msgspec

from services.scanner.can_codec import (
    Ack,
    AckResult,
    CanDecodeError,
    EndScan,
    FaroCodec,
    Frame,
    Inclinometer,
    InitiateScan,
    RecordPause,
    ScanProfile,
    ScanState,
    Status,
    default_codec,
)

log = logging.getLogger(__name__)

_TURN_S = 0.05


class ScannerError(Exception):
    """Base of the client's errors."""


class AckTimeout(ScannerError):
    """A command was not acknowledged after all its attempts."""


class CommandRejected(ScannerError):
    """The scanner acknowledged a command with a result other than OK."""


class ScannerStatus(msgspec.Struct, frozen=True, kw_only=True):
    """What the client knows about its current scan. ``error`` says why when
    ``state`` is ERROR; ``inclinometer`` is the reading sent at completion."""

    state: ScanState = ScanState.IDLE
    progress_pct: int = 0
    scan_id: int | None = None
    error: str = ""
    inclinometer: Inclinometer | None = None


class ScannerClient:
    """See the module docstring. ``ack_timeout_s`` is per attempt (wall time), so a
    command blocks for at most ``(1 + retries) * ack_timeout_s`` before raising
    :class:`AckTimeout`. ``stuck_timeout_s`` (no progress while scanning) and
    ``status_timeout_s`` (no status while scanning or paused) are on ``now``."""

    def __init__(
        self,
        bus: can.BusABC,
        *,
        now: Callable[[], float] = time.monotonic,
        ack_timeout_s: float = 0.5,
        retries: int = 2,
        stuck_timeout_s: float = 30.0,
        status_timeout_s: float = 3.0,
        codec: FaroCodec | None = None,
    ) -> None:
        self._bus = bus
        self._now = now
        self.ack_timeout_s = ack_timeout_s
        self.retries = retries
        self.stuck_timeout_s = stuck_timeout_s
        self.status_timeout_s = status_timeout_s
        self._codec = codec or default_codec()
        self._status = ScannerStatus()
        self._next_id = 1
        self._last_progress_t = 0.0
        self._last_status_t = 0.0
        self.decode_errors = 0

    @property
    def status(self) -> ScannerStatus:
        return self._status

    # --- commands ---

    def start_scan(self, profile: ScanProfile, scan_id: int | None = None) -> int:
        """Start a scan and return its id (``scan_id``, or the next of a counter).

        Blocks until acknowledged; raises :class:`AckTimeout` or
        :class:`CommandRejected` (e.g. BUSY while another scan runs)."""
        sid = self._next_id if scan_id is None else scan_id
        self._command(InitiateScan(scan_id=sid, profile=profile))
        self._next_id = (sid + 1) % 65536
        t = self._now()
        self._last_progress_t = self._last_status_t = t
        self._status = ScannerStatus(state=ScanState.SCANNING, scan_id=sid)
        return sid

    def pause(self) -> None:
        """Pause the scan in progress (blocks until acknowledged)."""
        self._command(RecordPause(pause=True))
        if self._status.state == ScanState.SCANNING:
            self._set(state=ScanState.PAUSED)

    def resume(self) -> None:
        """Resume a paused scan (blocks until acknowledged)."""
        self._command(RecordPause(pause=False))
        if self._status.state == ScanState.PAUSED:
            self._last_progress_t = self._now()
            self._set(state=ScanState.SCANNING)

    def stop(self) -> None:
        """End (abort) the scan in progress; it is then IDLE, never DONE. Blocks until
        acknowledged."""
        self._command(EndScan(scan_id=self._status.scan_id or 0))
        if self._status.state in (ScanState.SCANNING, ScanState.PAUSED):
            self._set(state=ScanState.IDLE)

    def _command(self, frame: Frame) -> None:
        cid = self._codec.frame_id(type(frame))
        name = type(frame).__name__
        msg = self._codec.encode(frame)
        attempts = 1 + self.retries
        send_error = ""  # why the last attempt could not even be sent (bus-off)
        for attempt in range(1, attempts + 1):
            try:
                self._bus.send(msg)
                send_error = ""
            except can.CanError as e:
                send_error = f"; sending failed: {e}"
                log.warning("sending %s failed (attempt %d/%d): %s", name, attempt, attempts, e)
            deadline = time.monotonic() + self.ack_timeout_s
            while (remaining := deadline - time.monotonic()) > 0:
                reply = self._receive(min(remaining, _TURN_S))
                if isinstance(reply, Ack) and reply.command_id == cid:
                    if reply.result != AckResult.OK:
                        raise CommandRejected(f"scanner rejected {name}: {reply.result.name}")
                    return
            log.warning("no ACK for %s (attempt %d/%d)", name, attempt, attempts)
        raise AckTimeout(
            f"no ACK for {name} after {attempts} attempts of {self.ack_timeout_s} s each"
            f"{send_error}"
        )

    # --- status tracking ---

    def poll(self, timeout_s: float = 0.0) -> ScannerStatus:
        """Process the frames already queued and those that arrive within
        ``timeout_s`` wall seconds, checking for a stuck or silent scan."""
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if self._receive(min(max(remaining, 0.0), _TURN_S)) is None and remaining <= 0:
                break
        return self._status

    def wait_finished(self, timeout_s: float) -> ScannerStatus:
        """Poll until the scan is DONE, ERROR or IDLE, or ``timeout_s`` passed (on
        ``now``); returns the status either way, the caller checks ``state``."""
        deadline = self._now() + timeout_s
        while self._status.state in (ScanState.SCANNING, ScanState.PAUSED):
            remaining = deadline - self._now()
            if remaining <= 0:
                break
            self._receive(min(remaining, _TURN_S))
        return self._status

    def _receive(self, timeout_s: float) -> Frame | None:
        """Receive and track one frame (``None`` when none came), then check the
        watchdogs. Bad frames are logged and counted, never raised."""
        msg = self._bus.recv(timeout_s)
        frame: Frame | None = None
        if msg is not None:
            try:
                frame = self._codec.decode(msg)
            except CanDecodeError as e:
                self.decode_errors += 1
                log.warning("ignoring bad CAN frame: %s", e)
        if isinstance(frame, Status):
            self._on_status(frame)
        elif isinstance(frame, Inclinometer) and frame.scan_id == self._status.scan_id:
            self._set(inclinometer=frame)
        self._watchdog()
        return frame

    def _on_status(self, s: Status) -> None:
        st = self._status
        if st.state not in (ScanState.SCANNING, ScanState.PAUSED) or s.scan_id != st.scan_id:
            return  # not about a scan we are running (stale, or one we ended)
        now = self._now()
        self._last_status_t = now
        if s.progress_pct != st.progress_pct:
            self._last_progress_t = now
        progress = s.progress_pct
        match s.state:
            case ScanState.SCANNING | ScanState.PAUSED:
                if s.state == ScanState.SCANNING and st.state == ScanState.PAUSED:
                    self._last_progress_t = now
                self._set(state=s.state, progress_pct=progress)
            case ScanState.DONE if progress == 100:
                self._set(state=ScanState.DONE, progress_pct=100)
            case ScanState.DONE:
                self._fail(f"scanner reported done at {progress}%")
            case ScanState.ERROR:
                self._fail(f"scanner error code {s.error_code} at {progress}%")
            case ScanState.IDLE:
                self._fail(f"scanner went idle at {progress}% without finishing")

    def _watchdog(self) -> None:
        st = self._status
        if st.state not in (ScanState.SCANNING, ScanState.PAUSED):
            return
        now = self._now()
        if now - self._last_status_t > self.status_timeout_s:
            self._fail(f"no status from scanner for {now - self._last_status_t:.1f} s")
        elif st.state == ScanState.SCANNING and now - self._last_progress_t > self.stuck_timeout_s:
            self._fail(f"scan stuck at {st.progress_pct}% for {now - self._last_progress_t:.1f} s")

    def _fail(self, reason: str) -> None:
        log.error("scan %s failed: %s", self._status.scan_id, reason)
        self._set(state=ScanState.ERROR, error=reason)

    def _set(self, **changes: object) -> None:
        self._status = msgspec.structs.replace(self._status, **changes)
