"""A FARO Focus automation-interface emulator that answers on a python-can bus.

It speaks the frames of ``faro.dbc``: an ACK after every command, a Status frame
every ``status_period_s`` (and at once on every state change), completion after the
profile's scan time, and an Inclinometer frame (just before the DONE status) when a
scan completes. Faults can be injected (:class:`FaroFaults`) so clients are tested
against a misbehaving device.

python-can's ``virtual`` interface only connects buses of one process, so the
emulator runs in a thread next to the client, on its own ``can.Bus`` instance of the
same channel. It never shuts the bus down: whoever created the bus owns it.

Command semantics (our choice; FARO does not publish them): Initiate for the scan
already in progress, Pause while paused and End while idle are acknowledged OK, so a
client may retry a command whose ACK was lost. Initiate while another scan runs is
BUSY; Pause/Resume with no scan is NOT_SCANNING; End for another scan id is
INVALID_PARAMETER. End aborts: the scan is not complete and no callback fires.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import can

from services.scanner.can_codec import (
    RESOLUTION_DIVISORS,
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
from services.scanner.sim.faults import FaroFaults, FaultBook, aimed

__all__ = ["STORAGE_ERROR_CODE", "FaroEmulator", "FaroFaults", "default_scan_duration_s"]

log = logging.getLogger(__name__)

# error code reported when the completed scan cannot be stored (our choice, see faro.dbc)
STORAGE_ERROR_CODE = 90


def default_scan_duration_s(profile: ScanProfile) -> float:
    """Rough FARO Focus scan time: ~30 min at full resolution and 1x quality, falling
    with the square of the resolution divisor and growing linearly with quality
    (1/4 resolution at 4x is then ~7.5 min, the commonly quoted figure)."""
    divisor = RESOLUTION_DIVISORS[profile.resolution_index]
    return 1800.0 * profile.quality / divisor**2


ScanCallback = Callable[[int, ScanProfile], None]


class FaroEmulator:
    """The emulated scanner. Use :meth:`start`/:meth:`stop` (or ``with``) to run it
    in a background thread, or call :meth:`step` yourself from one thread.

    ``now`` is the time source in seconds (a sim clock may drive it); scan progress
    and status periods follow it. ``on_scan_complete(scan_id, profile)`` runs in the
    emulator thread when a scan completes (not when it is ended or fails); an
    exception in it is logged and does not stop the emulator.
    """

    def __init__(
        self,
        bus: can.BusABC,
        *,
        now: Callable[[], float] = time.monotonic,
        scan_duration_s: Callable[[ScanProfile], float] = default_scan_duration_s,
        status_period_s: float = 0.1,
        faults: FaroFaults | None = None,
        on_scan_complete: ScanCallback | None = None,
        inclination_deg: Callable[[], tuple[float, float]] = lambda: (0.0, 0.0),
        codec: FaroCodec | None = None,
        timed: bool = True,
    ) -> None:
        # ``timed`` False: the scan advances (and completes, and reports its status)
        # only in :meth:`tick`, called on the owner's clock, not in the thread that
        # answers frames: in lockstep with a simulator that keeps it to the steps
        self._timed = timed
        self._lock = threading.RLock()
        self._bus = bus
        self._now = now
        self._duration = scan_duration_s
        self._status_period = status_period_s
        self.faults = faults or FaroFaults()
        self.on_scan_complete = on_scan_complete
        self._inclination = inclination_deg
        self._codec = codec or default_codec()
        self._ids = {k: self._codec.frame_id(k) for k in (InitiateScan, RecordPause, EndScan)}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._book = FaultBook(self.faults, now)
        self._was_off = False
        # Scan state; only the emulator thread touches it once started.
        self.state = ScanState.IDLE
        self.scan_id = 0
        self.error_code = 0
        self._profile = ScanProfile()
        self._scan_s = 1.0
        self._active_s = 0.0  # scanning time accumulated before the current segment
        self._segment_t0: float | None = None  # start of the current unpaused segment
        self._progress = 0.0
        self._last_status_t = -float("inf")

    # --- lifecycle ---

    def start(self) -> None:
        """Start the emulator thread (idempotent)."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="faro-emulator", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        """Stop the thread and wait for it (at most ``timeout_s``). Does not shut
        the bus down. Raises RuntimeError when the thread does not end in time."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        self._stop.set()
        thread.join(timeout_s)
        if thread.is_alive():
            raise RuntimeError(f"FARO emulator thread did not stop within {timeout_s} s")

    def __enter__(self) -> FaroEmulator:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.step(0.005)

    # --- one iteration ---

    def step(self, timeout_s: float = 0.0) -> None:
        """Handle at most one received frame (waiting up to ``timeout_s`` wall
        seconds for it), then advance the scan and send a status when due."""
        msg = self._bus.recv(timeout_s)
        with self._lock:
            if msg is not None:
                self._receive(msg)
            if self._timed:
                self.tick()

    def tick(self) -> None:
        """Advance the scan to now and send a status when one is due."""
        with self._lock:
            off = self.bus_off()
            if self._was_off and not off:
                log.warning("FARO emulator: bus-off over (fault)")
            self._was_off = off
            self._advance()
            if self._now() - self._last_status_t >= self._status_period:
                self._send_status()

    def _receive(self, msg: can.Message) -> None:
        if msg.arbitration_id not in self._ids.values() or msg.is_extended_id:
            return  # not addressed to the scanner (or our own replies on a loopback bus)
        if self.bus_off():
            return  # a bus-off node hears nothing
        try:
            frame = self._codec.decode(msg)
        except CanDecodeError as e:
            log.warning("FARO emulator ignores a bad command: %s", e)
            return
        f = self.faults
        sid = frame.scan_id if isinstance(frame, InitiateScan | EndScan) else self.scan_id
        if f.no_ack and aimed(f.no_ack_scan_ids, sid):
            return
        if self._book.lose_command(sid):
            log.info("FARO emulator: command lost (fault): %r", frame)
            return
        result = self._execute(frame)
        if self._book.lose_ack(sid):
            log.info("FARO emulator: ACK lost (fault) for %r", frame)
        else:
            self._send(Ack(command_id=msg.arbitration_id, result=result))
        self._send_status()
        if isinstance(frame, InitiateScan) and result == AckResult.OK:
            self._book.started(sid)

    def bus_off(self) -> bool:
        """Is the scanner's CAN node bus-off (the ``bus_off`` fault) now? Any thread."""
        return self._book.bus_off()

    def _execute(self, frame: Frame) -> AckResult:
        now = self._now()
        busy = self.state in (ScanState.SCANNING, ScanState.PAUSED)
        match frame:
            case InitiateScan(scan_id=sid, profile=profile):
                if busy:
                    return AckResult.OK if sid == self.scan_id else AckResult.BUSY
                self.state, self.scan_id, self.error_code = ScanState.SCANNING, sid, 0
                self._profile, self._scan_s = profile, max(self._duration(profile), 1e-6)
                self._active_s, self._segment_t0, self._progress = 0.0, now, 0.0
            case RecordPause(pause=pause):
                if not busy:
                    return AckResult.NOT_SCANNING
                if pause and self.state == ScanState.SCANNING:
                    self._advance()
                    self._active_s += now - (self._segment_t0 or now)
                    self._segment_t0, self.state = None, ScanState.PAUSED
                elif not pause and self.state == ScanState.PAUSED:
                    self._segment_t0, self.state = now, ScanState.SCANNING
            case EndScan(scan_id=sid):
                if busy and sid != self.scan_id:
                    return AckResult.INVALID_PARAMETER
                if busy:
                    self.state, self._segment_t0 = ScanState.IDLE, None
        return AckResult.OK

    def _advance(self) -> None:
        if self.state != ScanState.SCANNING or self._segment_t0 is None:
            return
        active = self._active_s + self._now() - self._segment_t0
        progress = min(100.0, 100.0 * active / self._scan_s)
        f = self.faults
        if f.stuck_at_pct is not None and aimed(f.stuck_scan_ids, self.scan_id):
            progress = min(progress, f.stuck_at_pct, 99.0)
        failing = f.error_code and aimed(f.error_scan_ids, self.scan_id)
        if failing and progress >= f.error_at_pct:
            self._progress = f.error_at_pct
            self.state, self.error_code, self._segment_t0 = ScanState.ERROR, f.error_code, None
            self._send_status()
        else:
            self._progress = progress
            if progress >= 100.0:
                self._complete()

    def _complete(self) -> None:
        # The scan is written to the card before DONE is reported (a simulator renders
        # it in the callback); a failed write fails the scan with STORAGE_ERROR_CODE.
        if self.on_scan_complete is not None:
            try:
                self.on_scan_complete(self.scan_id, self._profile)
            except Exception:
                log.exception("scan %d could not be stored", self.scan_id)
                self.state, self.error_code = ScanState.ERROR, STORAGE_ERROR_CODE
                self._segment_t0 = None
                self._send_status()
                return
        self.state, self._segment_t0 = ScanState.DONE, None
        # Inclinometer first, so a client that sees DONE already has the reading.
        pitch, roll = self._inclination()
        self._send(Inclinometer(pitch_deg=pitch, roll_deg=roll, scan_id=self.scan_id))
        self._send_status()

    def _send_status(self) -> None:
        self._last_status_t = self._now()
        self._send(
            Status(
                state=self.state,
                # Floor, so 100 % is reported only once the scan is really complete.
                progress_pct=int(self._progress),
                error_code=self.error_code,
                scan_id=self.scan_id,
            )
        )

    def _send(self, frame: Frame) -> None:
        if self.bus_off():
            return  # what a bus-off node transmits is lost
        try:
            self._bus.send(self._codec.encode(frame))
        except can.CanError as e:
            log.warning("FARO emulator could not send %s: %s", type(frame).__name__, e)
