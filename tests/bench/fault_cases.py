"""The fault campaign's cases (run by tests/bench/fault_campaign.py): what each
injects, what it expects, and how it judges the survey against the simulator's truth."""

from __future__ import annotations

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


# --- the cases ---
def kill_case(service: str, phase: str) -> Case:
    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        extra = "[services.viz]\nsave = ''\n" if service == "viz" else ""
        d = Deployment(procs, tmp, extra, hz=FIELD_HZ, home=True)
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
            os.kill(pid_of(d, service), signal.SIGKILL)
            at = truth.samples[-1]
            still = truth.still_after(at.stamp_ns)
            if still is None:
                return False, "never stood still", {}
            dt = (still.stamp_ns - at.stamp_ns) / 1e9
            dist = math.hypot(still.x - at.x, still.y - at.y)
            floor_s, floor_m = braking(at.v, STILL)
            figs = {"stop_s": dt, "stop_m": dist, "speed_at_kill": at.v}
            figs |= {"drivetrain_s": floor_s, "drivetrain_m": floor_m}
            text = (
                f"stood {dt:.2f} s and {100 * dist:.1f} cm after the kill, from {at.v:.2f} m/s "
                f"(the drivetrain alone: {floor_s:.2f} s, {100 * floor_m:.1f} cm; "
                f"the software's part: {dt - floor_s:.2f} s)"
            )
            return dt <= 0.5 and dist <= 0.2, text, figs
        finally:
            d.close()

    return Case(
        f"stop-{service}-killed",
        f"SIGKILL {service} while driving (real time, field timers)",
        "the robot (truth) stands within 0.5 s and 0.2 m",
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


def periodic(
    kind: str, first_s: float, every_s: float, for_s: float, n: int, more: str = ""
) -> str:
    """``n`` windows of a sim fault: the survey's timing is not known in advance, so the
    fault recurs and the robot meets it driving, settling and scanning alike."""
    return "".join(
        f"[[services.sim.faults]]\nkind = '{kind}'\nat_s = {first_s + k * every_s}\n"
        f"for_s = {for_s}\n{more}"
        for k in range(n)
    )


def fault_case(
    name: str,
    fault: str,
    expectation: str,
    sim: str = "",
    scanner: str = "",
    rtf: float = 20.0,
    failed: tuple[int, ...] = (),
    stops: tuple[float, float] | None = None,
) -> Case:
    """A survey under a scheduled sim fault (``sim``: ``[[services.sim.faults]]``
    entries) or scanner fault (``scanner``: ``sim_faults`` keys). Expectation: the
    survey completes, the scans ``failed`` (ids) failed and every other one done within
    tolerance by the truth; with ``stops`` = (kind's windows' first at_s, every_s),
    the robot stood within 1 s of each window that began while it drove."""

    def run(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
        extra = (f"[services.scanner.sim_faults]\n{scanner}\n" if scanner else "") + sim
        d = Deployment(procs, tmp, extra, rtf=rtf, field_timers=rtf <= 4, hz=FIELD_HZ, home=True)
        try:
            truth = Truth(d)
            s = d.start()
            final = finish(d, s.mission, timeout=1200)
            steps = MissionLog(d.runs / s.mission / "mission.db").steps()
            want_failed = [st.scan_id for st in steps if st.status == "failed"]
            ok, text, figs = survey_verdict(d, s.mission, truth)
            if failed:
                ok = want_failed == list(failed) and figs["done"] == figs["total"] - len(failed)
                text += f"; failed: {want_failed}"
            if stops is not None:
                worst, met = stop_times(truth, *stops)
                figs |= {"worst_stop_s": worst, "outages_met_driving": met}
                text += f"; {met} outages began while driving, stood within {worst:.2f} s"
                ok = ok and met > 0 and worst <= 1.0  # a fault never met is no pass
            return ok and final.phase == MissionPhase.DONE, text, figs
        finally:
            d.close()

    return Case(name, fault, expectation, run)


def stop_times(truth: Truth, first_s: float, every_s: float) -> tuple[float, int]:
    """The longest time from a fault window's start to standing, over the windows that
    began while the robot drove (|v| > 0.1 m/s), and how many did."""
    worst, met = 0.0, 0
    k = 0
    samples = truth.samples
    while samples and first_s + k * every_s < samples[-1].stamp_ns / 1e9:
        t0 = int((first_s + k * every_s) * 1e9)
        k += 1
        before = [p for p in samples if p.stamp_ns <= t0]
        if not before or abs(before[-1].v) <= 0.1:
            continue
        met += 1
        still = next((p for p in samples if p.stamp_ns > t0 and abs(p.v) < STILL), None)
        worst = max(worst, math.inf if still is None else (still.stamp_ns - t0) / 1e9)
    return worst, met


def more_than(n: int) -> Callable[[list[TruthPose]], bool]:
    return lambda ms: len(ms) > n


def fuzz_deployment(procs: Procs, tmp: Path) -> tuple[bool, str, dict[str, float]]:
    """30 s of garbage on every key of the table (topics and queries): random bytes,
    other types, non-finite values; and nav's absurd well-typed inputs. Velocity
    commands and e-stops get only what cannot decode: a well-typed one would drive the
    robot legitimately, which access control, not decoding, must prevent."""
    import random

    import msgspec

    from common.messages.system import Health
    from tests.integration.test_fuzz import TOPIC_KEYS, absurd

    d = Deployment(procs, tmp, hz=FIELD_HZ, home=True)
    try:
        truth = Truth(d)
        beats: Record[Health] = record(d.bus, keys.HEALTH.at(service="*"))
        poses: list[float] = []
        d.bus.subscribe(keys.NAV_POSE, lambda p: poses.extend((p.x, p.y, p.yaw, p.v, p.w)))
        rng = random.Random(7)
        topics = [k.replace("{antenna}", "1").replace("{service}", "x") for k in keys.TOPICS]
        rpcs = [k.replace("{service}", "nav") for k in keys.RPCS]
        bad = [msgspec.msgpack.encode({"x": math.nan, "stamp_ns": -1}), b"\xc1", b""]
        t_end, n = time.monotonic() + 30.0, 0
        while time.monotonic() < t_end:
            key = rng.choice(topics)
            if key in TOPIC_KEYS and rng.random() < 0.5:
                data = absurd(rng, key, truth.samples[-1].stamp_ns if truth.samples else 0)
            else:
                data = rng.choice([rng.randbytes(rng.randrange(64)), *bad])
            d.bus.put_raw(key, data)
            if n % 50 == 0:
                list(d.session.get(rng.choice(rpcs), payload=rng.choice(bad), timeout=0.5))
            n += 1
            if n % 3 == 0:  # paced by the world: three per true pose (200 Hz at 20x)
                truth.samples.until(more_than(len(truth.samples)), timeout=1.0)
        # every service's heartbeat from after the fuzz, with its final counts
        end = time.time_ns()
        names = ("nav", "base", "gnss", "mission")
        beats.until(lambda hs: {h.service for h in hs if h.stamp_ns > end} >= set(names), 10)
        health = {h.service: h for h in list(beats)}
        moved = max((abs(p.v) for p in truth.samples), default=0.0)
        restarts = d.log.read_text().count("restarting service")
        finite = all(math.isfinite(v) for v in poses)
        rejects = {s: h.decode_errors + h.callback_errors for s, h in health.items()}
        counted = all(rejects.get(s, 0) > 0 for s in names)
        ok = restarts == 0 and finite and moved < STILL and counted and bool(poses)
        text = (
            f"{n} messages; {restarts} restarts; estimate finite: {finite}; robot's top "
            f"speed {moved:.3f} m/s; rejects counted: {rejects}"
        )
        return ok, text, {"messages": n, "restarts": restarts, "top_speed": moved}
    finally:
        d.close()


FAULTS: list[Case] = [
    Case(
        "fuzz-every-key",
        "30 s of random bytes, wrong types, non-finite and absurd values on every key",
        "no crash or restart, no non-finite estimate, rejects counted, the robot stands",
        fuzz_deployment,
    ),
    fault_case(
        "rtk-outage",
        "RTK outage, both antennas, 20 s every 37 s (4x, field timers)",
        "stands within 1 s of an outage met driving; no scan on a bad pose; completes",
        sim=periodic("rtk_outage", 30.0, 37.0, 20.0, 40),
        rtf=4.0,
        stops=(30.0, 37.0),
    ),
    fault_case(
        "rtk-float",
        "RTK float on antenna 2, 30 s every 90 s",
        "float is not fused: waits it out; completes, scans within tolerance",
        sim=periodic("rtk_float", 40.0, 90.0, 30.0, 10, "antenna = 2\n"),
    ),
    fault_case(
        "multipath",
        "0.4 m jump on antenna 1 reported as RTK fixed, 5 s every 60 s",
        "the EKF gates the jump; completes, scans within tolerance",
        sim=periodic("multipath", 30.0, 60.0, 5.0, 15, "antenna = 1\noffset_m = [0.4, 0.0]\n"),
    ),
    fault_case(
        "odometry-freeze",
        "wheel encoders read zero, 10 s every 70 s",
        "completes, scans within tolerance",
        sim=periodic("odometry_freeze", 35.0, 70.0, 10.0, 12),
    ),
    fault_case(
        "scanner-error",
        "FARO error code 42 on every attempt at scan 2",
        "scan 2 failed after its retries, the others done; completes",
        scanner="error_code = 42\nerror_scan_ids = [2]",
        failed=(2,),
    ),
    fault_case(
        "scanner-stuck",
        "scan 2 stuck at 40 % on every attempt",
        "the stuck scan is noticed (no wait outlives its deadline); scan 2 failed; completes",
        scanner="stuck_at_pct = 40.0\nstuck_scan_ids = [2]",
        failed=(2,),
    ),
    fault_case(
        "scanner-lost-acks",
        "the first 3 CAN ACKs lost",
        "commands resent; completes, every scan done",
        scanner="lose_first_acks = 3",
    ),
    fault_case(
        "can-bus-off",
        "CAN bus-off for 8 s during scan 2",
        "completes, every scan done",
        scanner="bus_off_for_s = 8.0\nbus_off_scan_ids = [2]",
    ),
]


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
    *FAULTS,
]
