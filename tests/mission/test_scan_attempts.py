"""A retried scan is recorded from its own end, never from the previous attempt's.

The scanner republishes its state every tick, stamped by its own clock; a status it
stamped before answering the retry's StartScan may reach the mission after that answer
(delivery under load), and says DONE for the same scan id as the attempt the mission
just rejected. The mission's clock cannot judge such a status: two processes' clocks
differ by seconds under load. Once, a retried scan was recorded from that DONE while the
real scan was taken on the drive to the next location, 4 m away.

Here a scanner on the bus runs its clock 5 s ahead of the mission's (or, as a Jetson
whose clock was never set would, a minute behind it) and, for a second after
answering, keeps delivering what it stamped before the answer: the previous attempt's
DONE. The retry must wait for its own DONE (another file). And an attempt that is not
recorded (the pose over it was off) leaves its step out of ``scanning``: a mission
restarted then must not take that scan from the scanner.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import msgspec
import pytest

from common import keys
from common.clock import WallClock
from common.messages.nav import PoseEstimate
from common.messages.scan import ScannerReply, ScannerState, ScannerStatus, StartScan, StopScan
from common.missionlog import Step
from common.service import Context
from common.transport import Bus
from services.mission.config import MissionConfig
from services.mission.feeds import Feeds
from services.mission.log import MissionLog
from services.mission.survey import Survey
from tests.conftest import client

NS = 1_000_000_000
X, Y = 10.5, 2.0  # the planned location


class OffsetScanner:
    """A scanner whose clock runs ``offset_ns`` ahead, left DONE by a first attempt at
    scan 1 (``first.e57``). A StartScan is answered at once; for ``late_s`` after the
    answer the statuses delivered are those stamped before it (the old DONE), then
    it scans for ``scan_s`` and ends DONE with ``second.e57``. It also publishes the
    navigation's pose, localized ``off_m`` east of the planned location, as a standing
    robot's."""

    def __init__(
        self,
        bus: Bus,
        offset_ns: int,
        off_m: float = 0.0,
        late_s: float = 1.0,
        scan_s: float = 1.0,
        hangs: str = "",
    ) -> None:
        """``hangs``: ``scanner`` or ``nav`` falls silent once the scan is under way
        (SIGSTOP, or a link that drops): its newest message stays the newest held."""
        self.bus, self.late_s, self.scan_s, self.hangs = bus, late_s, scan_s, hangs
        self.offset_ns, self.off_m = offset_ns, off_m
        self.replied_ns: int | None = None  # the scanner's stamp of its answer
        self.replied_wall = 0.0
        self.stop = threading.Event()
        self._status = bus.publisher(keys.SCANNER_STATUS)
        self._pose = bus.publisher(keys.NAV_POSE)
        bus.serve(keys.SCANNER_CMD, self._command)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def close(self) -> None:
        self.stop.set()
        self._thread.join()

    def now(self) -> int:
        return time.time_ns() + self.offset_ns

    def _command(self, cmd: object) -> ScannerReply:
        if isinstance(cmd, StopScan):  # a lost attempt is stopped
            return ScannerReply(ok=True, stamp_ns=self.now())
        assert isinstance(cmd, StartScan), cmd
        self.replied_wall = time.monotonic()
        self.replied_ns = self.now()
        return ScannerReply(ok=True, stamp_ns=self.replied_ns)

    def status(self) -> ScannerStatus:
        old = ScannerStatus(state=ScannerState.DONE, scan_id=1, progress=1.0, file="first.e57")
        if self.replied_ns is None:
            return msgspec.structs.replace(old, stamp_ns=self.now())
        since = time.monotonic() - self.replied_wall
        if since < self.late_s:  # stamped before the answer, delivered after it
            return msgspec.structs.replace(old, stamp_ns=self.replied_ns - NS // 10)
        if since < self.late_s + self.scan_s:
            p = (since - self.late_s) / self.scan_s
            return ScannerStatus(
                state=ScannerState.SCANNING, scan_id=1, progress=p, stamp_ns=self.now()
            )
        return ScannerStatus(
            state=ScannerState.DONE, scan_id=1, progress=1.0, file="second.e57", stamp_ns=self.now()
        )

    def _run(self) -> None:
        while not self.stop.wait(0.05):
            st = self.status()
            hung = st.state == ScannerState.SCANNING and st.progress > 0.01
            if not (hung and self.hangs == "scanner"):  # else its last SCANNING is held
                self._status.put(st)
            if not (hung and self.hangs == "nav"):
                pose = PoseEstimate(x=X + self.off_m, y=Y, yaw=0.0, localized=True)
                self._pose.put(msgspec.structs.replace(pose, stamp_ns=self.now()))


@pytest.fixture
def scanner_bus(router_endpoint: str) -> Iterator[Bus]:
    with client(router_endpoint, "scanner") as bus:
        yield bus


def retry(
    bus: Bus, tmp_path: Path, scanner: OffsetScanner, cfg: MissionConfig | None = None
) -> tuple[str, Step, list[str]]:
    """The retry of scan 1 at (X, Y): why it failed ("" if not) and its step after."""
    log = MissionLog(tmp_path / "mission.db")
    log.create("m", "tiny", 0, "{}", [(1, 0, X, Y, 0.0)])
    # the first attempt ended without a usable pose: this is the retry
    log.update(0, status="scanning", attempts=1)
    events: list[str] = []
    ctx = Context("mission", "test", bus, WallClock(), logging.getLogger("t"), tmp_path)
    wake, abort, paused = threading.Event(), threading.Event(), threading.Event()
    report = lambda lv, t: events.append(f"{lv}: {t}")  # noqa: E731
    cfg = cfg or MissionConfig()
    survey = Survey(ctx, cfg, Feeds(bus), log, "m", report, wake, abort, paused)
    try:
        seen = survey.scanner.wait_for(lambda s: s.file == "first.e57", timeout=10)
        assert seen is not None, "the scanner's status never reached the mission"
        why = survey.scans.scan(log.steps()[0], cfg.profile)
        return why, log.steps()[0], events
    finally:
        scanner.close()
        wake.set()
        log.close()


@pytest.mark.parametrize("offset_s", [5, -60], ids=["scanner-5s-ahead", "scanner-1min-behind"])
def test_a_retried_scan_waits_for_its_own_done(
    client_bus: Bus, scanner_bus: Bus, tmp_path: Path, offset_s: int
) -> None:
    scanner = OffsetScanner(scanner_bus, offset_s * NS)
    why, recorded, events = retry(client_bus, tmp_path, scanner)
    assert why == "", (why, events)
    assert recorded.status == "done"
    assert recorded.file == "second.e57", "recorded from the previous attempt's DONE"
    # the pose the scan is placed with: the standing robot's estimate at the scan's end
    assert (recorded.pose_x, recorded.pose_y, recorded.pose_yaw) == pytest.approx((X, Y, 0.0))
    assert scanner.replied_ns is not None


def test_a_scan_taken_off_the_plan_is_not_left_for_a_restart_to_take(
    client_bus: Bus, scanner_bus: Bus, tmp_path: Path
) -> None:
    scanner = OffsetScanner(scanner_bus, 0, off_m=0.2)
    why, step, events = retry(client_bus, tmp_path, scanner)
    assert "not recorded as done" in why, (why, events)
    # "scanning" would let a restarted mission record the scanner's DONE of it
    assert step.status == "driving", step


def test_a_standing_robot_whose_estimate_wandered_past_the_arrival_check_keeps_its_scan(
    client_bus: Bus, scanner_bus: Bus, tmp_path: Path
) -> None:
    """Over the scan the estimate may wander beyond the 5 cm an arrival is held to
    (the fixes under the crop); standing still within ``scan_tolerance_m`` the scan
    sees what the plan asked for and is kept."""
    cfg = MissionConfig()
    assert cfg.arrival_tolerance_m < 0.07 < cfg.scan_tolerance_m
    scanner = OffsetScanner(scanner_bus, 0, off_m=0.07)
    why, step, events = retry(client_bus, tmp_path, scanner, cfg)
    assert why == "" and step.status == "done", (why, events)


@pytest.mark.parametrize(
    ("hangs", "why"),
    [
        ("scanner", "scanner lost the scan (no status for it in 1 s)"),
        ("nav", "no pose from navigation for 1 s: the pose over the scan is unknown"),
    ],
)
def test_a_peer_that_hangs_mid_scan_is_noticed_by_the_age_of_what_it_said(
    client_bus: Bus, scanner_bus: Bus, tmp_path: Path, hangs: str, why: str
) -> None:
    """A scanner or navigation that hangs mid-scan leaves its last word the newest
    held; the attempt is lost within the deadline, not at the scan's 30-minute limit."""
    scanner = OffsetScanner(scanner_bus, 0, late_s=0.2, scan_s=60.0, hangs=hangs)
    cfg = MissionConfig(scanner_lost_s=1.0, nav_lost_s=1.0, rpc_timeout_s=1.0)
    t0 = time.monotonic()
    got, step, events = retry(client_bus, tmp_path, scanner, cfg)
    assert got == why, events
    # the scan is 60 s long: lost after its deadline (1 s) and the stop call to a
    # scanner that may not answer (rpc_timeout_s, 1 s), not at its end
    assert time.monotonic() - t0 < 45.0  # a fail-safe: the scan's end would be 60 s
    assert step.status == "driving", step
