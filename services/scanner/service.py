"""The scanner service's Zenoh shell: typed commands in (each waits for the device's
ACK), status out; a scan is reported done only when the device finished it."""

from __future__ import annotations

import math
import threading

from common import clock as clk
from common import keys
from common.messages.core import SCANNER_FRAME
from common.messages.scan import (
    PauseScan,
    ScannerCommand,
    ScannerReply,
    ScannerState,
    ScannerStatus,
    StartScan,
    StopScan,
)
from common.service import Context
from common.transport import RequestError
from services.scanner.can_codec import RESOLUTION_DIVISORS, ScanProfile, ScanState
from services.scanner.client import ScannerClient, ScannerError
from services.scanner.config import ScannerConfig
from services.scanner.device import open_device, scan_path

_STATES = {
    ScanState.IDLE: ScannerState.IDLE,
    ScanState.SCANNING: ScannerState.SCANNING,
    ScanState.PAUSED: ScannerState.PAUSED,
    ScanState.DONE: ScannerState.DONE,
    ScanState.ERROR: ScannerState.ERROR,
}


class ScannerService:
    def __init__(self, ctx: Context, cfg: ScannerConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        self.device = open_device(ctx, cfg)
        self.client = ScannerClient(
            self.device.bus,
            now=lambda: ctx.clock.now_ns() / 1e9,
            ack_timeout_s=cfg.ack_timeout_s,
            retries=cfg.retries,
            stuck_timeout_s=cfg.stuck_timeout_s,
            status_timeout_s=cfg.status_timeout_s,
        )
        self._lock = threading.Lock()  # the client is single-threaded
        self._bus_error = ""  # what is wrong with the CAN bus, as last reported
        # 1 while the bus is failing: a supervisor sees it in health/scanner
        ctx.bus.report("can_bus_error", lambda: int(bool(self._bus_error)))
        self.status_pub = ctx.bus.publisher(keys.SCANNER_STATUS)
        ctx.bus.serve(keys.SCANNER_CMD, self.handle)

    def handle(self, cmd: ScannerCommand) -> ScannerReply:
        try:
            with self._lock:
                match cmd:
                    case StartScan(profile=p, project=project):
                        if p.resolution not in RESOLUTION_DIVISORS:
                            raise RequestError(
                                f"ScanProfile.resolution: 1/{p.resolution} is not "
                                f"one of 1/{RESOLUTION_DIVISORS}"
                            )
                        prof = ScanProfile(
                            resolution_index=RESOLUTION_DIVISORS.index(p.resolution),
                            quality=p.quality,
                        )
                        self.device.project = project
                        self.client.start_scan(prof, scan_id=p.scan_id)
                        self.ctx.log.info("scan %s/%d started", project or ".", p.scan_id)
                    case PauseScan():
                        self.client.pause()
                    case StopScan():
                        self.client.stop()
                # stamped under the lock, as every status is: a status stamped after
                # this reply was polled after the command (the mission relies on it)
                stamp = self.ctx.clock.now_ns()
        except ScannerError as exc:
            raise RequestError(f"scanner: {exc}") from None
        return ScannerReply(stamp_ns=stamp, ok=True)

    def status(self) -> ScannerStatus:
        with self._lock:
            s = self.client.poll(0.0)
            stamp = self.ctx.clock.now_ns()
        sid = s.scan_id or 0
        done = s.state == ScanState.DONE and sid > 0
        inc = s.inclinometer
        return ScannerStatus(
            stamp_ns=stamp,
            frame_id=SCANNER_FRAME,
            state=_STATES[s.state],
            scan_id=sid,
            progress=min(1.0, max(0.0, s.progress_pct / 100.0)),
            error=s.error,
            file=str(scan_path(self.cfg.storage_dir, sid, self.device.project).resolve())
            if done
            else "",
            pitch=math.radians(inc.pitch_deg) if done and inc is not None else 0.0,
            roll=math.radians(inc.roll_deg) if done and inc is not None else 0.0,
        )

    def _report_bus(self) -> None:
        """Say in one line when the CAN bus fails (bus-off, error passive) and when it
        is back."""
        with self._lock:
            now = self.device.bus_error()
        if now and now != self._bus_error:
            self.ctx.log.warning("scanner CAN bus: %s", now)
        elif self._bus_error and not now:
            self.ctx.log.info("scanner CAN bus: back")
        self._bus_error = now

    def run(self, stop: threading.Event) -> None:
        last: tuple[ScannerState, str] | None = None
        try:
            for _ in clk.ticks(self.ctx.clock, self.cfg.status_hz, stop):
                self._report_bus()
                st = self.status()
                if (st.state, st.error) != last:
                    log = (
                        self.ctx.log.warning
                        if st.state == ScannerState.ERROR
                        else self.ctx.log.info
                    )
                    log("scanner %s%s", st.state.value, f": {st.error}" if st.error else "")
                    last = (st.state, st.error)
                self.status_pub.put(st)
        finally:
            self.device.close()


def build(ctx: Context, cfg: ScannerConfig) -> ScannerService:
    return ScannerService(ctx, cfg)
