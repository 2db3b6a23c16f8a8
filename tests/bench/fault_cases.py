"""The fault campaign's cases (run by tests/bench/fault_campaign.py): what each
injects, what it expects, and how it judges the survey against the simulator's truth."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

from common import keys
from common.client import wait_alive
from common.messages.mission import MissionPhase, MissionState
from common.messages.nav import NavState
from common.messages.sim import TruthPose
from phenorover.eval.register.truth import read_truth
from services.mission.log import MissionLog
from services.nav.follower_config import FollowerConfig
from tests.bench.drivetrain import braking
from tests.conftest import Procs, Record, record
from tests.integration.test_mission import Deployment

TOLERANCE_M = 0.05  # the mission's arrival tolerance
# the shipped simulator and base rates (deploy/sim.toml, the base's default): the
# campaign judges the deployment as shipped, not the tests' lighter 20 Hz
FIELD_HZ = 50.0
STILL = 0.02  # m/s: below it the drivetrain's lag leaves millimetres to roll


@dataclasses.dataclass(frozen=True)
class Case:
    name: str
    fault: str
    expectation: str
    run: Callable[[Procs, Path], tuple[bool, str, dict[str, float]]]


# --- what the cases observe ---
class Truth:
    def __init__(self, d: Deployment) -> None:
        self.samples: Record[TruthPose] = record(d.bus, keys.SIM_TRUTH)

    def still_after(self, t_ns: int, timeout: float = 30.0) -> TruthPose | None:
        """The first true pose after ``t_ns`` with the robot standing."""

        def still(p: TruthPose) -> bool:
            return p.stamp_ns > t_ns and abs(p.v) < STILL

        self.samples.until(lambda ms: any(still(p) for p in ms[-50:]), timeout)
        return next((p for p in list(self.samples) if still(p)), None)


def survey_verdict(d: Deployment, mission: str, truth: Truth) -> tuple[bool, str, dict[str, float]]:
    """Every location done once, its true pose during the scan within tolerance."""
    log = MissionLog(d.runs / mission / "mission.db")
    steps = log.steps()
    integrity = log.db.execute("PRAGMA integrity_check").fetchone()[0]
    log.close()
    worst = 0.0
    unseen: list[int] = []  # done scans with no truth at all: not judged, so not passed
    for i, st in enumerate(steps):
        if st.status != "done" or st.started_ns is None or st.ended_ns is None:
            continue
        # the bus's true poses over the scan, where they reached this process (a cut
        # link drops them), and the pose the simulator wrote beside the scan's file
        offsets = [
            math.hypot(t.x - st.x, t.y - st.y)
            for t in truth.samples
            if st.started_ns <= t.stamp_ns <= st.ended_ns
        ]
        scan_truth = read_truth(st.file) if st.file else None
        if scan_truth is not None:
            offsets.append(math.hypot(scan_truth.x - st.x, scan_truth.y - st.y))
        if offsets:
            worst = max(worst, *offsets)
        else:
            unseen.append(i + 1)
    done = sum(st.status == "done" for st in steps)
    files_ok = all(st.file and Path(st.file).is_file() for st in steps if st.status == "done")
    ok = (
        done == len(steps)
        and worst <= TOLERANCE_M
        and not unseen
        and integrity == "ok"
        and files_ok
    )
    text = (
        f"{done}/{len(steps)} done, true pose during scans within {100 * worst:.1f} cm, "
        f"mission.db {integrity}{'' if files_ok else ', a scan file missing'}"
        + (f", no truth for scans {unseen}" if unseen else "")
    )
    return ok, text, {"done": done, "total": len(steps), "worst_true_offset_m": worst}


def finish(d: Deployment, mission: str, timeout: float = 600) -> MissionState:
    s = d.wait(
        lambda x: x.mission == mission and x.phase in (MissionPhase.DONE, MissionPhase.FAILED),
        timeout=timeout,
    )
    return s


def pid_of(d: Deployment, service: str) -> int:
    return next(a.pid for a in wait_alive(d.session, {service}, 10).seen if a.service == service)


def wait_driving(d: Deployment, scan: int) -> None:
    progress = d.bus.latest(keys.NAV_PROGRESS)
    d.wait(lambda x: x.phase == MissionPhase.DRIVING and x.current_scan == scan)
    got = progress.wait_for(
        lambda p: f".{scan}." in p.route_id and p.state == NavState.DRIVING, timeout=120
    )
    assert got is not None, "never drove toward the location"


def survey_deployment(procs: Procs, tmp: Path, service: str, top: str = "") -> Deployment:
    """The deployment a case of ``service`` surveys with (viz records nothing: a
    recording is no subject of these cases); ``top``: top-level manifest keys."""
    extra = "[services.viz]\nsave = ''\n" if service == "viz" else ""
    return Deployment(procs, tmp, extra, hz=FIELD_HZ, home=True, top=top)


def reach(d: Deployment, phase: str) -> None:
    """Wait until the survey is ``driving`` to scan 2 or ``scanning`` it."""
    if phase == "driving":
        wait_driving(d, 2)
    else:
        d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 2)


# --- the cases ---
def kill_case(service: str, phase: str) -> Case:
    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        d = survey_deployment(procs, tmp, service)
        try:
            truth = Truth(d)
            s = d.start()
            reach(d, phase)
            os.kill(pid_of(d, service), signal.SIGKILL)
            finish(d, s.mission)
            ok, text, figs = survey_verdict(d, s.mission, truth)
            restarts = d.log.read_text().count(f"restarting service {service}")
            return ok and restarts >= 1, f"{text}; {service} restarted {restarts}x", figs
        finally:
            d.close()

    return Case(
        f"kill-{service}-{phase}",
        f"SIGKILL {service} while {phase}",
        "restarted; survey completes, every location done once, true pose within 5 cm",
        run,
    )


def stop_case(
    service: str,
    sig: signal.Signals = signal.SIGKILL,
    limit: tuple[float, float] = (0.5, 0.2),
    software_s: float | None = None,
) -> Case:
    """The robot driving at cruise when ``service`` is killed (or frozen: SIGSTOP, and
    SIGCONT once measured): it must stand within ``limit`` (s, m) by the truth; with
    ``software_s``, the time beyond the drivetrain's own stop from the speed met must
    be within it instead (a bound set by a timer, not by braking)."""
    frozen = sig == signal.SIGSTOP

    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        # real time: at 4x every millisecond of delivery and scheduling is four of sim time
        # and truth at 50 Hz, so that a stop is timed to 20 ms rather than 100 ms
        d = Deployment(
            procs, tmp, rtf=1.0, field_timers=True, sim="truth_hz = 50.0", hz=FIELD_HZ, home=True
        )
        try:
            truth = Truth(d)
            d.start()
            wait_driving(d, 2)
            # at cruise: the wheels' forward slip keeps the body about 1 % under it
            cruise = 0.95 * FollowerConfig().max_speed
            at_speed = truth.samples.until(lambda ms: bool(ms) and abs(ms[-1].v) >= cruise, 60)
            assert at_speed, f"the robot never reached {cruise:.2f} m/s"
            pid = pid_of(d, service)
            os.kill(pid, sig)
            at = truth.samples[-1]
            still = truth.still_after(at.stamp_ns)
            if frozen:
                with contextlib.suppress(ProcessLookupError):  # the launcher replaced it
                    os.kill(pid, signal.SIGCONT)
            if still is None:
                return False, "never stood still", {}
            dt = (still.stamp_ns - at.stamp_ns) / 1e9
            dist = math.hypot(still.x - at.x, still.y - at.y)
            floor_s, floor_m = braking(at.v, STILL)
            figs = {"stop_s": dt, "stop_m": dist, "speed_at_kill": at.v}
            figs |= {"drivetrain_s": floor_s, "drivetrain_m": floor_m}
            text = (
                f"stood {dt:.2f} s and {100 * dist:.1f} cm after the {what}, from {at.v:.2f} m/s "
                f"(the drivetrain alone: {floor_s:.2f} s, {100 * floor_m:.1f} cm; "
                f"the software's part: {dt - floor_s:.2f} s)"
            )
            if software_s is not None:
                return dt - floor_s <= software_s, text, figs
            return dt <= limit[0] and dist <= limit[1], text, figs
        finally:
            d.close()

    what = "freeze" if frozen else "kill"
    return Case(
        f"stop-{service}-{'frozen' if frozen else 'killed'}",
        f"{sig.name} {service} while driving (real time, field timers)",
        f"the robot (truth) stands within {limit[0]:g} s and {limit[1]:g} m"
        if software_s is None
        else f"the robot (truth) stands within {software_s:g} s beyond the drivetrain's own stop",
        run,
    )


def power_cut(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
    """Every process SIGKILLed mid-scan at once, the launcher too; then the launcher
    is started again, as after a reboot. The world has no power to lose: the
    simulator, killed with the rest, continues its world from its snapshot (a named
    deployment lets it across launchers)."""
    os.environ["PHENOROVER_SIM_DEPLOYMENT"] = f"power-cut-{os.getpid()}-{time.time_ns()}"
    d = Deployment(procs, tmp, hz=FIELD_HZ, home=True)
    try:
        truth = Truth(d)
        s = d.start()
        d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 2)
        # the services first: a launcher that dies first sends them SIGTERM, and a
        # power cut lets nobody shut down cleanly
        for a in wait_alive(d.session, {"mission"}, 10).seen:
            os.kill(a.pid, signal.SIGKILL)
        d.up.kill()
        d.up.wait()
        d.up = procs.start("-m", "phenorover", "up", str(tmp / "m.toml"), log=tmp / "up2.log")
        final = finish(d, s.mission)
        ok, text, figs = survey_verdict(d, s.mission, truth)
        resumed = "resuming mission" in (tmp / "up2.log").read_text()
        done = final.phase == MissionPhase.DONE
        return ok and resumed and done, f"{text}; resumed by itself: {resumed}", figs
    finally:
        d.close()
        del os.environ["PHENOROVER_SIM_DEPLOYMENT"]


CASES: list[Case] = [
    *(
        kill_case(s, p)
        for p in ("driving", "scanning")
        for s in ("sim", "gnss", "base", "nav", "scanner", "mission", "planner", "viz")
    ),
    stop_case("nav"),
    stop_case("mission"),
    # a frozen nav or base commands nothing: the base's watchdog or the motors' own
    # timeout stop the wheels (0.25 s each; a killed nav is noticed sooner, its
    # liveliness token goes with its link), within the 1 s; a frozen mission
    # drives nothing itself, and the route navigation follows runs out with its lease (2 s)
    stop_case("nav", signal.SIGSTOP, (1.0, 0.2)),
    stop_case("base", signal.SIGSTOP, (1.0, 0.2)),
    stop_case("mission", signal.SIGSTOP, software_s=2.5),  # the lease, 2 s, and 0.5 s
    Case(
        "power-cut-mid-scan",
        "every service and the launcher SIGKILLed mid-scan, launcher started again",
        "resumes by itself; every scan within tolerance; files whole; integrity ok",
        power_cut,
    ),
]
