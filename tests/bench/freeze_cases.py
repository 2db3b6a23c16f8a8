"""The fault campaign's frozen-process cases: a service stopped by SIGSTOP (a process
that hangs, or a machine whose link drops) rather than killed, so that nothing on the
bus says it is gone until what it last said grows old.

Each service is frozen during a survey of the tiny field, while driving and while
scanning, and sent SIGCONT once the launcher has replaced it. Judged: the launcher
noticed the silent heartbeat within ``hung_after_s`` (wall time; 5 s here, see
:data:`HUNG_AFTER_S`) and restarted the service; the survey completed with every
location done once and its true pose within tolerance; and, for the scanner frozen
mid-scan, the mission gave the attempt up within 15 s of sim time (``scanner_lost_s``
is 10 s). Where the robot must stand when the frozen service commands motion is timed
by the real-time stop cases (``stop-<service>-frozen`` in
:mod:`tests.bench.fault_cases`).
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import threading
import time
from pathlib import Path

from common import keys
from common.messages.mission import MissionEvent
from tests.bench.fault_cases import (
    Case,
    Truth,
    finish,
    pid_of,
    reach,
    survey_deployment,
    survey_verdict,
)
from tests.conftest import Procs, Record, record

# The launcher's limit here, wall time: at 20x the shipped 10 s is 200 s of sim time,
# in which a mission that waits on a frozen nav gives its route up (route_time_s, 300 s
# of sim time, is a field allowance in sim time); 5 s is 100 s of sim time. In the
# field sim and wall time are one, and the shipped 10 s stands.
HUNG_AFTER_S = 5.0
# what the cases hold the launcher to: hung_after_s, plus the heartbeat's period (1 s)
# and the launcher's check of its children (every 0.1 s), with a margin for a busy
# machine
NOTICE_S = HUNG_AFTER_S + 2.0
SCANNER_DEADLINE_S = 15.0  # sim time: the bound for the scanner mid-scan
LOST = "scanner lost the scan"


def noticed_after(log: Path, service: str, pid: int, since: float, timeout: float) -> float:
    """Wall seconds from ``since`` until the launcher's log says it took ``pid`` for
    hung (inf if it never did within ``timeout``)."""
    line = re.compile(rf"service {service} \(pid {pid}\) has not been heard for")
    wake = threading.Event()
    while time.monotonic() - since < timeout:
        if line.search(log.read_text(errors="replace")):
            return time.monotonic() - since
        wake.wait(0.1)  # the launcher's log is a file: read it again shortly
    return float("inf")


def freeze_case(service: str, phase: str) -> Case:
    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        d = survey_deployment(procs, tmp, service, f"hung_after_s = {HUNG_AFTER_S}")
        try:
            truth = Truth(d)
            events: Record[MissionEvent] = record(d.bus, keys.MISSION_EVENT)
            s = d.start()
            reach(d, phase)
            pid = pid_of(d, service)
            frozen_ns = truth.samples[-1].stamp_ns if truth.samples else 0
            t0 = time.monotonic()
            os.kill(pid, signal.SIGSTOP)
            noticed = noticed_after(d.log, service, pid, t0, HUNG_AFTER_S + 30.0)
            with contextlib.suppress(ProcessLookupError):  # replaced: it is gone
                os.kill(pid, signal.SIGCONT)
            finish(d, s.mission, timeout=900)
            ok, text, figs = survey_verdict(d, s.mission, truth)
            restarts = d.log.read_text().count(f"restarting service {service}")
            ok = ok and noticed <= NOTICE_S and restarts >= 1
            figs |= {"noticed_wall_s": noticed, "restarts": restarts}
            text += f"; hung noticed by the launcher after {noticed:.1f} s, restarted {restarts}x"
            if service == "scanner" and phase == "scanning":
                lost = next((e for e in list(events) if LOST in e.text), None)
                gave_up = (lost.stamp_ns - frozen_ns) / 1e9 if lost else float("inf")
                figs["attempt_lost_sim_s"] = gave_up
                text += f"; the mission gave the scan attempt up after {gave_up:.1f} s (sim)"
                ok = ok and gave_up <= SCANNER_DEADLINE_S
            return ok, text, figs
        finally:
            d.close()

    expectation = (
        f"noticed (heartbeat silent {HUNG_AFTER_S:.0f} s) within {NOTICE_S:.0f} s, replaced; "
        "survey completes, "
        "every location done once, true pose within 5 cm"
    )
    if service == "scanner" and phase == "scanning":
        expectation += f"; the attempt given up within {SCANNER_DEADLINE_S:.0f} s"
    return Case(
        f"freeze-{service}-{phase}",
        f"SIGSTOP {service} while {phase}, SIGCONT once replaced",
        expectation,
        run,
    )


CASES: list[Case] = [
    freeze_case(s, p)
    for p in ("driving", "scanning")
    for s in ("sim", "gnss", "base", "nav", "scanner", "mission", "planner", "viz")
]
