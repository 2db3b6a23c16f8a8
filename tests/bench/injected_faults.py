"""The fault campaign's injected faults (run by tests/bench/fault_campaign.py): sim
faults on a schedule (RTK outages and float, multipath, frozen odometry), the scanner's
faults, and garbage on every key, each during a survey of the tiny field."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

from common import keys
from common.messages.mission import MissionPhase
from common.messages.sim import TruthPose
from services.mission.log import MissionLog
from tests.bench.fault_cases import FIELD_HZ, STILL, Case, Truth, finish, survey_verdict
from tests.conftest import Procs, Record, record
from tests.integration.test_mission import Deployment


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
