"""Scanning at a location, for the survey loop (:mod:`services.mission.survey`): one
attempt at a scan, waited for and recorded, and a scan found on the scanner after the
mission restarted. A scan is recorded as done only where the pose over it was where
planned; the device is stopped whenever an attempt is given up, since a scanner still
busy with it would refuse the next.
"""

from __future__ import annotations

import math

from common import keys
from common.clock import NS
from common.messages.nav import PoseEstimate
from common.messages.scan import ScannerState, ScannerStatus, ScanProfile, StartScan, StopScan
from common.missionlog import Step
from common.transport import RpcError
from services.mission.port import SurveyPort
from services.mission.stats import pose_stats, scan_pose, tilt_stats


class Scans:
    """The scans of one survey ``sv``, on its clock, calls and pose collection."""

    def __init__(self, sv: SurveyPort) -> None:
        self.sv = sv

    def found_on_scanner(self, step: Step) -> bool:
        """A step the mission left in ``scanning`` (it restarted): True, and recorded,
        when the scanner finished that scan, or finishes the one it is still taking,
        and the robot stands where planned; never a second scan of a location that
        has one."""
        t0 = self.sv.now()
        while (st := self.sv.scanner.get()) is None:  # a restarted mission hears it soon
            if (self.sv.now() - t0) / NS > self.sv.cfg.scanner_lost_s:
                self.sv.event("warning", f"scan {step.scan_id}: no word from the scanner")
                return False
            t0 += self.sv.wait(0.1)
        if st.scan_id != step.scan_id or st.state not in (ScannerState.DONE, ScannerState.SCANNING):
            self.sv.event("info", f"scan {step.scan_id}: scanner at {st.scan_id}, {st.state}")
            return False
        p = self.sv.settle()
        if p is None or self.sv.off_by(step, p.x, p.y) > self.sv.cfg.arrival_tolerance_m:
            where = "no pose" if p is None else f"{100 * self.sv.off_by(step, p.x, p.y):.1f} cm off"
            self.sv.event(
                "warning", f"scan {step.scan_id}: on the scanner, but the robot is {where}"
            )
            return False
        what = "done" if st.state == ScannerState.DONE else "still scanning"
        self.sv.event("info", f"scan {step.scan_id}: found {what} on the scanner after a restart")
        if st.state == ScannerState.DONE:
            return not self.record(step, st, [p])
        self.sv.collect([p])  # the pose over the rest of the scan
        try:  # only statuses the scanner stamped after the one just seen
            return not self._await(step, st.stamp_ns)
        finally:
            self.sv.collect(None)

    def scan(self, step: Step, prof: ScanProfile) -> str:
        """One attempt at ``step``'s scan: "" when done and recorded, else why not."""
        self.sv.log.update(
            step.idx, status="scanning", attempts=step.attempts + 1, started_ns=self.sv.now()
        )
        self.sv.collect([])
        try:
            took = self.sv.call(keys.SCANNER_CMD, StartScan(profile=prof, project=self.sv.mission))
        except RpcError as exc:
            # a device still busy with a failed scan (stuck, say) refuses the next:
            # end whatever it is doing before the next attempt
            self.stop()
            self.sv.wait(2.0)
            return f"start failed: {exc}"
        try:
            why = self._await(step, took.stamp_ns)
        finally:
            self.sv.collect(None)
        if why:
            # no longer "scanning": a mission restarted now must not take this
            # attempt's scan from the scanner (its DONE may be one rejected here, taken
            # off the plan or while moving); it positions and scans again
            self.sv.log.update(step.idx, status="driving")
        return why

    def _await(self, step: Step, since_ns: int) -> str:
        """Wait for ``step``'s scan to end and record it. ``since_ns``: a stamp of the
        scanner's own clock (its reply to this attempt's StartScan, or a status of the
        scan already seen); only statuses it stamped later speak of this attempt. The
        scanner republishes its state every tick, so the previous attempt's DONE (same
        scan id) keeps fresh stamps until the start is handled, and the mission's clock
        is no judge of them: under load two processes' sim clocks differ by seconds,
        and in the field the scanner's computer keeps its own time (a retried scan was
        once recorded from such a DONE while the real one was taken on the drive to the
        next location)."""
        t0 = seen = self.sv.now()
        heard_ns = since_ns  # the scanner's stamp of the newest status taken as heard
        while True:
            paused = self.sv.wait(0.2)
            t0, seen = t0 + paused, seen + paused
            now = self.sv.now()
            if (now - t0) / NS > self.sv.cfg.scan_timeout_s:
                self.stop()
                return f"no end in {self.sv.cfg.scan_timeout_s:.0f} s"
            if self.sv.pose_age_s() > (lost := self.sv.cfg.nav_lost_s):
                why = f"no pose from navigation for {lost:.0f} s: the pose over the scan is unknown"
                return self._give_up(step, why)
            st = self.sv.scanner.get()
            # Only a status stamped after the last one heard is word from the scanner:
            # one from before this attempt (a retry follows an error for the same scan
            # id) says nothing about it, and the newest status held is held forever
            # by a scanner that hangs (or whose link drops) while "scanning".
            fresh = st is not None and st.stamp_ns > heard_ns
            if not fresh or st is None or st.scan_id != step.scan_id:
                if (now - seen) / NS > (lost := self.sv.cfg.scanner_lost_s):
                    why = f"scanner lost the scan (no status for it in {lost:.0f} s)"
                    return self._give_up(step, why)
                continue
            seen, heard_ns = now, st.stamp_ns
            if st.state == ScannerState.ERROR:
                # the service gave up on the scan (stuck, silent); the device may still
                # be taking it, and would refuse the next one as busy
                self.stop()
                self.sv.wait(1.0)
                return f"scanner error: {st.error}"
            if st.state == ScannerState.DONE:
                return self.record(step, st, self.sv.collected())

    def _give_up(self, step: Step, why: str) -> str:
        """Give the attempt up for ``why``, said at once: the stop that follows waits up
        to ``rpc_timeout_s`` on a scanner that may not answer (it hangs)."""
        self.sv.event("warning", f"scan {step.scan_id}: {why}; stopping the scanner")
        self.stop()  # a device still scanning would refuse the retry
        return why

    def record(self, step: Step, st: ScannerStatus, poses: list[PoseEstimate]) -> str:
        """Record the scan as done if the pose over it was where planned: its mean
        within the scan tolerance, its spread within half the arrival tolerance (the
        robot stood still), localized for at least half the scan (a standing robot's
        estimate rides out a short RTK float on zero-velocity updates; the statistics
        use the localized poses only)."""
        good = [p for p in poses if p.localized]
        if 2 * len(good) < max(len(poses), 1):
            return f"localized for only {len(good)} of {len(poses)} poses during the scan"
        stats = pose_stats(good)
        off = self.sv.off_by(step, stats["mean_x"], stats["mean_y"])
        moved = math.hypot(stats["sd_x"], stats["sd_y"])
        if off > self.sv.cfg.scan_tolerance_m or moved > self.sv.cfg.arrival_tolerance_m / 2:
            return (
                f"pose during the scan {100 * off:.1f} cm off the plan "
                f"(SD {100 * moved:.1f} cm): not recorded as done"
            )
        self.sv.log.update(
            step.idx,
            status="done",
            file=st.file,
            ended_ns=self.sv.now(),
            pitch=st.pitch,
            roll=st.roll,
            **stats,
            **tilt_stats(good),
            **scan_pose(good, self.sv.cfg.scan_pose),
        )
        return ""

    def stop(self) -> None:
        try:
            self.sv.ctx.bus.call(keys.SCANNER_CMD, StopScan(), timeout=self.sv.cfg.rpc_timeout_s)
        except RpcError as exc:
            self.sv.event("warning", f"scanner: stop failed: {exc}")
