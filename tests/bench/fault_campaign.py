"""The fault campaign (``make faults``): each fault and each service kill during a
survey of the tiny test field, with every service its own process under
``phenorover up``, judged against the simulator's truth. Writes
``runs/bench/faults.json`` and the table in ``docs/faults.md`` (fault, expectation,
observed, verdict; date, commit, machine). About half an hour on two cores.

    python tests/bench/fault_campaign.py [--only NAME ...] [--json OUT] [--no-docs]

Survey cases run the sim at 20x real time with the safety timers given their field
allowance in wall time (see tests/integration/test_mission.py ``Deployment``); the
stop cases, which measure how fast the robot stands after a fault, run at 4x with
the field's own timers. The verdict of a case is its expectation, checked; a case
that crashes is a fail with the exception as what was observed.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from common import keys  # noqa: E402
from common.cli import wait_alive  # noqa: E402
from common.messages.mission import MissionPhase, MissionState  # noqa: E402
from common.messages.nav import NavState  # noqa: E402
from common.messages.sim import TruthPose  # noqa: E402
from services.mission.log import MissionLog  # noqa: E402
from tests.conftest import Procs  # noqa: E402
from tests.integration.test_mission import Deployment  # noqa: E402

TOLERANCE_M = 0.05  # the mission's arrival tolerance
STILL = 0.02  # m/s: below it the drivetrain's lag leaves millimetres to roll


@dataclasses.dataclass
class Result:
    name: str
    fault: str
    expectation: str
    observed: str = ""
    passed: bool = False
    seconds: float = 0.0
    figures: dict[str, float] = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class Case:
    name: str
    fault: str
    expectation: str
    run: Callable[[Procs, Path], tuple[bool, str, dict[str, float]]]


# --- what the cases observe ---
class Truth:
    def __init__(self, d: Deployment) -> None:
        self.samples: list[TruthPose] = []
        d.bus.subscribe(keys.SIM_TRUTH, self.samples.append)

    def still_after(self, t_ns: int, timeout: float = 30.0) -> TruthPose | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            s = next((p for p in self.samples if p.stamp_ns > t_ns and abs(p.v) < STILL), None)
            if s is not None:
                return s
            time.sleep(0.1)  # polling a recording, not synchronising a test
        return None


def survey_verdict(d: Deployment, mission: str, truth: Truth) -> tuple[bool, str, dict[str, float]]:
    """Every location done once, its true pose during the scan within tolerance."""
    log = MissionLog(d.runs / mission / "mission.db")
    steps = log.steps()
    integrity = log.db.execute("PRAGMA integrity_check").fetchone()[0]
    log.close()
    worst = 0.0
    for st in steps:
        if st.status != "done" or st.started_ns is None or st.ended_ns is None:
            continue
        during = [t for t in truth.samples if st.started_ns <= t.stamp_ns <= st.ended_ns]
        if during:
            worst = max(worst, max(math.hypot(t.x - st.x, t.y - st.y) for t in during))
    done = sum(st.status == "done" for st in steps)
    files_ok = all(st.file and Path(st.file).is_file() for st in steps if st.status == "done")
    ok = done == len(steps) and worst <= TOLERANCE_M and integrity == "ok" and files_ok
    text = (
        f"{done}/{len(steps)} done, true pose during scans within {100 * worst:.1f} cm, "
        f"mission.db {integrity}{'' if files_ok else ', a scan file missing'}"
    )
    return ok, text, {"done": done, "total": len(steps), "worst_true_offset_m": worst}


def finish(d: Deployment, mission: str, timeout: float = 600) -> MissionState:
    s = d.wait(
        lambda x: x.mission == mission and x.phase in (MissionPhase.DONE, MissionPhase.FAILED),
        timeout=timeout,
    )
    return s


def pid_of(d: Deployment, service: str) -> int:
    return next(a.pid for a in wait_alive(d.session, {service}, 10) if a.service == service)


def wait_driving(d: Deployment, scan: int) -> None:
    progress = d.bus.latest(keys.NAV_PROGRESS)
    d.wait(lambda x: x.phase == MissionPhase.DRIVING and x.current_scan == scan)
    got = progress.wait_for(
        lambda p: f".{scan}." in p.route_id and p.state == NavState.DRIVING, timeout=120
    )
    assert got is not None, "never drove toward the location"


# --- the cases ---
def kill_case(service: str, phase: str) -> Case:
    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        extra = "[services.viz]\nsave = ''\n" if service == "viz" else ""
        d = Deployment(procs, tmp, extra)
        try:
            truth = Truth(d)
            s = d.start()
            if phase == "driving":
                wait_driving(d, 2)
            else:
                d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 2)
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


def stop_case(service: str) -> Case:
    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        d = Deployment(procs, tmp, rtf=4.0, field_timers=True)
        try:
            truth = Truth(d)
            d.start()
            wait_driving(d, 2)
            while not truth.samples or abs(truth.samples[-1].v) < 0.3:
                time.sleep(0.05)  # polling a recording: until the robot is at speed
            os.kill(pid_of(d, service), signal.SIGKILL)
            at = truth.samples[-1]
            still = truth.still_after(at.stamp_ns)
            if still is None:
                return False, "never stood still", {}
            dt = (still.stamp_ns - at.stamp_ns) / 1e9
            dist = math.hypot(still.x - at.x, still.y - at.y)
            figs = {"stop_s": dt, "stop_m": dist, "speed_at_kill": at.v}
            text = f"stood {dt:.2f} s and {100 * dist:.1f} cm after the kill, from {at.v:.2f} m/s"
            return dt <= 0.5 and dist <= 0.2, text, figs
        finally:
            d.close()

    return Case(
        f"stop-{service}-killed",
        f"SIGKILL {service} while driving (4x, field timers)",
        "the robot (truth) stands within 0.5 s and 0.2 m",
        run,
    )


def power_cut(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
    """Every process SIGKILLed mid-scan at once, the launcher too; then the launcher
    is started again, as after a reboot. The world has no power to lose: the
    simulator, killed with the rest, continues its world from its snapshot (a named
    deployment lets it across launchers)."""
    os.environ["PHENOROVER_SIM_DEPLOYMENT"] = f"power-cut-{os.getpid()}-{time.time_ns()}"
    d = Deployment(procs, tmp)
    try:
        truth = Truth(d)
        s = d.start()
        d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 2)
        # the services first: a launcher that dies first sends them SIGTERM, and a
        # power cut lets nobody shut down cleanly
        for a in wait_alive(d.session, {"mission"}, 10):
            os.kill(a.pid, signal.SIGKILL)
        d.up.kill()
        d.up.wait()
        d.up = procs.start("-m", "common.cli", "up", str(tmp / "m.toml"), log=tmp / "up2.log")
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
    Case(
        "power-cut-mid-scan",
        "every service and the launcher SIGKILLed mid-scan, launcher started again",
        "resumes by itself; every scan within tolerance; files whole; integrity ok",
        power_cut,
    ),
]


def commit() -> str:
    r = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True
    )
    return r.stdout.strip() or "unknown"


def render(results: list[Result]) -> str:
    head = (
        f"Generated by `make faults` on {time.strftime('%Y-%m-%d')}, commit {commit()}, "
        f"{platform.node()} ({os.cpu_count()} cores); error models as in the README.\n\n"
        "| case | fault | expectation | observed | verdict |\n|---|---|---|---|---|\n"
    )
    rows = [
        f"| {r.name} | {r.fault} | {r.expectation} | {r.observed} | "
        f"{'pass' if r.passed else '**fail**'} |"
        for r in results
    ]
    n = sum(r.passed for r in results)
    return head + "\n".join(rows) + f"\n\n{n} of {len(results)} cases pass.\n"


MARK = "## Campaign results"


def write_docs(table: str) -> None:
    path = REPO / "docs" / "faults.md"
    text = path.read_text() if path.exists() else "# Faults\n"
    text = text.split(MARK)[0].rstrip() + f"\n\n{MARK}\n\n" + table
    path.write_text(text)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=None, help="case names (prefixes)")
    ap.add_argument("--json", type=Path, default=REPO / "runs" / "bench" / "faults.json")
    ap.add_argument("--no-docs", action="store_true")
    args = ap.parse_args()
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    cases = [c for c in CASES if not args.only or any(c.name.startswith(o) for o in args.only)]
    results = []
    for case in cases:
        res = Result(case.name, case.fault, case.expectation)
        t0 = time.monotonic()
        procs = Procs()
        with tempfile.TemporaryDirectory(prefix=f"fault-{case.name}-") as tmp:
            try:
                res.passed, res.observed, res.figures = case.run(procs, Path(tmp))
            except Exception as exc:
                res.observed = f"error: {type(exc).__name__}: {str(exc).splitlines()[0][:200]}"
                traceback.print_exc()
            finally:
                procs.stop_all()
        res.seconds = time.monotonic() - t0
        results.append(res)
        verdict = "pass" if res.passed else "FAIL"
        print(f"{case.name}: {verdict} ({res.seconds:.0f} s): {res.observed}", flush=True)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps([dataclasses.asdict(r) for r in results], indent=1))
    if not args.no_docs and not args.only:
        write_docs(render(results))
    return 0 if all(r.passed for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
