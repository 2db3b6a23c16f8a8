"""The survey's walk through its locations, in tour order, as the mission log lists
them: position, scan (with retries, each re-checking the pose) and record each one;
a location a restart left mid-scan is taken from the scanner when it finished there;
the battery is looked at before each drive (:mod:`.battery`); a location whose way
another robot blocks while waiting for this one is put off until the others
(:mod:`.lanes`).
The mission service (:mod:`.service`) runs it on its worker thread and owns the
phase, the events and what happens before and after."""

from __future__ import annotations

import logging
import threading
from collections import Counter
from typing import Protocol

import msgspec

from common.clock import Clock
from common.messages.mission import MissionPhase
from services.mission.battery import BatteryWatch
from services.mission.config import MissionConfig
from services.mission.feeds import Aborted
from services.mission.lanes import GiveWay
from services.mission.log import MissionLog
from services.mission.plan import Segment
from services.mission.survey import Survey

# how many times a location gives way to another robot before it waits its turn
GIVE_WAY_TIMES = 3


class Host(Protocol):
    """What the walk reports to: the service's phase and current scan, its events."""

    phase: MissionPhase
    current: int
    detail: str

    def event(self, level: str, text: str) -> None: ...


def walk(
    host: Host,
    log: MissionLog,
    sv: Survey,
    cfg: MissionConfig,
    segs: list[Segment],
    wake: threading.Event,
    battery: BatteryWatch | None = None,
) -> None:
    """Every location not finished yet; raises Aborted when ``wake`` is set before a
    location is begun. ``battery`` sees every location before the robot drives to it
    (and may send the robot for a swap first)."""
    by_cand = {s.cand_id: s for s in segs if s.cand_id is not None}
    todo = [s.idx for s in log.steps() if s.status not in ("done", "failed", "skipped")]
    gave_way: Counter[int] = Counter()
    while todo:
        step = log.steps()[todo.pop(0)]
        if wake.is_set():  # aborted while planning: not one route sent
            raise Aborted
        host.current = step.scan_id
        tag = f"scan {step.scan_id} (location {step.cand_id})"
        if step.status == "scanning":
            host.phase = MissionPhase.SETTLING
            if sv.scans.found_on_scanner(step):
                host.event("info", f"{tag}: done")
                continue
            # whatever the scanner holds for it is not taken after another restart
            log.update(step.idx, status="driving")
        seg = by_cand[step.cand_id]
        # a drive to a battery swap has nowhere else to go: it never gives way
        sv.give_way = False
        if battery is not None and log.steps()[step.idx].status in ("pending", "driving"):
            seg = battery.before(step, seg)
        # another robot and this one wait for each other: this one goes elsewhere
        # first, a few times a location, and then waits its turn
        sv.give_way = bool(todo) and gave_way[step.idx] < GIVE_WAY_TIMES
        try:
            visit(host, log, sv, cfg, step.idx, seg, tag)
        except GiveWay as exc:
            gave_way[step.idx] += 1
            host.event("info", f"{tag}: later: {exc}")
            todo.append(step.idx)


def visit(
    host: Host, log: MissionLog, sv: Survey, cfg: MissionConfig, idx: int, seg: Segment, tag: str
) -> None:
    """Position, scan (with retries, each re-checking the pose), record."""
    step = log.steps()[idx]
    drive = step.status in ("pending", "driving")
    if drive:
        log.update(idx, status="driving")
    why = ""
    for _ in range(step.attempts, cfg.scan_retries + 1):
        host.phase = MissionPhase.DRIVING if drive else MissionPhase.SETTLING
        why = sv.position(log.steps()[idx], seg, tag, drive_first=drive)
        if why:
            log.update(idx, status="skipped", reason=f"location not reached: {why}")
            host.event("error", f"{tag}: skipped, location not reached: {why}")
            return
        host.phase = MissionPhase.SCANNING
        prof = msgspec.structs.replace(cfg.profile, scan_id=log.steps()[idx].scan_id)
        why = sv.scans.scan(log.steps()[idx], prof)
        if not why:
            host.event("info", f"{tag}: done")
            return
        host.event("warning", f"{tag}: {why}")
        drive = False  # position() drives again when the robot is off
    log.update(idx, status="failed", reason=why)
    host.event("error", f"{tag}: failed after {cfg.scan_retries + 1} attempts: {why}")


def return_home(host: Host, sv: Survey, segs: list[Segment]) -> None:
    """Drive the plan's last segment, back to where the tour began (the Origin, or a
    fleet robot's home); a failure is reported, not raised: the scans are taken."""
    home = [s for s in segs if s.cand_id is None]
    if not home:
        return
    host.phase, host.detail, host.current = MissionPhase.RETURNING, "to Origin", 0
    sv.detail = host.detail
    sv.give_way = False  # the way home has nowhere else to go
    ok, why = sv.drive(home[0], f"{sv.mission}.home")
    if not ok:
        host.event("error", f"return to the Origin: {why}")


def clock_started(clock: Clock, stop: threading.Event, log: logging.Logger) -> bool:
    """Wait for the clock (a sim clock reads 0 until the simulator is heard): every
    wait of a resumed survey takes its deadline from it, and one taken at 0 has long
    passed when the first message comes. False when ``stop`` is set first."""
    if clock.wait_started(0.0):
        return True
    log.info("waiting for the clock before resuming")
    while not stop.is_set():
        if clock.wait_started(0.5):
            return True
    return False
