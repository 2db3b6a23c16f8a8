"""Whole surveys of a small field with every service as its own process under
``phenorover up``: complete, killed mid-scan and resumed, a failing scanner (with the
dashboard's recording), pause and resume from a second process, a malformed plan."""

from __future__ import annotations

import itertools
import math
import os
import re
import signal
import subprocess
import sys
import tomllib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest
import zenoh

from common import keys
from common.client import wait_alive
from common.config import zenoh_config
from common.messages.mission import MissionPhase, MissionStart, MissionState
from common.messages.nav import NavState
from common.messages.sim import TruthPose
from common.rpc import until_served
from common.transport import Bus, RpcError
from services.mission.log import MissionLog
from tests.conftest import REPO, Procs, free_port, record
from tests.viz import rrd

TINY = REPO / "tests" / "data" / "tiny.toml"
SERVICES = {"sim", "gnss", "base", "scanner", "nav", "planner", "mission"}
# the simulator's step and the base's rate in whole-survey tests: nav's own 20 Hz (see
# Deployment's ``hz``)
TEST_HZ = 20.0


class Deployment:
    """The tiny field surveyed by every service under ``phenorover up``, the sim
    running ``rtf`` times faster than real time. Safety timers run on sim time, so
    at high ``rtf`` they get the field's allowance in *wall* time (a process late by
    50 ms of wall time is late by a second of sim time at 20x); ``field_timers``
    keeps the field's own values instead (meaningful at low ``rtf`` only). ``sim``:
    more lines for the ``[services.sim]`` table. ``host`` and ``wrap``: the router's
    address and a command to run the deployment under (another network namespace).
    ``hz``: the simulator's physics and clock step and the base's rate; 20 Hz, the rate
    nav steers at, keeps seven processes at 20x within two cores (at the shipped 50 Hz
    nav falls behind its odometry), and the fault campaign asks for the shipped 50.
    ``home``: drive back to the Origin after the last scan, as shipped (the campaign);
    the tests leave that leg to test_any_field's ``phenorover sim``. ``top``: more
    top-level manifest keys."""

    def __init__(
        self,
        procs: Procs,
        tmp: Path,
        extra: str = "",
        rtf: float = 20.0,
        field_timers: bool = False,
        sim: str = "",
        host: str = "127.0.0.1",
        wrap: Sequence[str] = (),
        hz: float = TEST_HZ,
        home: bool = False,
        top: str = "",
    ) -> None:
        self.tmp, self.port = tmp, free_port()
        self.runs = tmp / "runs"
        tmp.mkdir(parents=True, exist_ok=True)
        manifest = tmp / "m.toml"
        wall = 0.0 if field_timers else rtf
        watchdog = f"watchdog_s = {0.05 * wall}" if wall else ""
        fix_age = f"max_fix_age_s = {0.15 * wall}" if wall else ""
        # a route lease and navigation's silence during a scan: a second of wall time;
        # the scanner's silence: two, as its own status timeout (a mission restarted on
        # two busy cores may hear its first status later than 10 s of sim time, 0.5 s
        # of wall time at 20x, and would take the scan it is resuming for lost)
        lease = (
            f"lease_s = {1.0 * wall}\nnav_lost_s = {1.0 * wall}\nscanner_lost_s = {2.0 * wall}"
            if wall
            else ""
        )
        manifest.write_text(f"""machine = "test"
{top}
clock = "sim"
field = "{TINY}"
run_dir = "{self.runs}"
[zenoh]
listen = ["tcp/{host}:{self.port}"]
[services.sim]
real_time_factor = {rtf}
clock_hz = {hz}
{sim}
[services.gnss]
backend = "sim"
# open sky: what these surveys are asked does not depend on the crop's shading of
# the antennas, which only lengthens every fine positioning
rtk.canopy.noise_gain = 0.0
[services.base]
backend = "sim"
rate_hz = {hz}
{watchdog}
[services.scanner]
backend = "sim"
storage_dir = "{tmp / "card"}"
sim_scan_time_s = 20.0
render_step_deg = 1.0
status_timeout_s = {2.0 * rtf}  # sim seconds: 2 s of wall time on two busy cores
[services.nav]
{fix_age}
[services.planner]
[services.mission]
settle_s = 1.0
return_to_origin = {str(home).lower()}
{lease}
{extra}""")
        self.log = tmp / "up.log"
        self.up = procs.start("-m", "phenorover", "up", str(manifest), log=self.log, wrap=wrap)
        self.session = zenoh.open(zenoh_config("client", [], [f"tcp/{host}:{self.port}"]))
        self.bus = Bus(self.session, "test")
        assert wait_alive(self.session, SERVICES, timeout=60), "deployment did not come up"
        self.state = self.bus.latest(keys.MISSION_STATE)

    def start(self, **kw: Any) -> MissionState:
        cmd = MissionStart(field=str(TINY), **kw)
        return until_served(lambda: self.bus.call(keys.MISSION_CMD, cmd, timeout=120), 60.0)

    def wait(self, pred: object, timeout: float = 240) -> MissionState:
        s = self.state.wait_for(pred, timeout=timeout)  # type: ignore[arg-type]
        assert s is not None, f"mission state not reached; last {self.state.get()}"
        return s

    def close(self) -> None:
        if not self.session.is_closed():
            self.bus.close()
            self.session.close()

    def stop(self) -> None:
        """Stop the whole deployment as its operator would (SIGTERM to ``phenorover
        up``), whatever it was doing."""
        self.close()
        self.up.send_signal(signal.SIGTERM)
        self.up.wait(timeout=30)

    def scans_started(self) -> list[int]:
        return [
            int(m)
            for m in re.findall(r"scanner \| .* scan (?:\S+/)?(\d+) started", self.log.read_text())
        ]


@pytest.fixture
def deployment(
    procs: Procs, tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[Deployment]:
    d = Deployment(procs, tmp_path, getattr(request, "param", ""))
    yield d
    d.close()


def db(d: Deployment, mission: str) -> MissionLog:
    return MissionLog(d.runs / mission / "mission.db")


def test_complete_mission_with_pause_and_resume_from_another_process(
    deployment: Deployment,
) -> None:
    d = deployment
    d.runs.mkdir(exist_ok=True)
    bad = d.runs / "bad.json"
    bad.write_text('{"field": "tiny"}')
    with pytest.raises(RpcError, match=r"MissionStart\.plan_file: .*bad\.json"):
        d.start(plan_file=str(bad))
    with pytest.raises(RpcError, match=r"MissionStart\.plan_file: .* outside the run folder"):
        d.start(plan_file="/etc/passwd")
    with pytest.raises(RpcError, match=r"MissionStart\.field: .* not this deployment's field"):
        d.bus.call(keys.MISSION_CMD, MissionStart(field="spl"), timeout=60)
    assert not list(d.runs.glob("*/mission.db")), "a malformed plan started something"

    s = d.start()
    assert s.scans_total == 3
    d.wait(lambda x: x.mission == s.mission and x.phase == MissionPhase.SCANNING)
    cli = [sys.executable, "-m", "phenorover", "mission", "--connect", f"tcp/127.0.0.1:{d.port}"]
    r = subprocess.run([*cli, "pause"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "paused" in r.stdout, r.stderr
    paused = d.wait(lambda x: x.phase == MissionPhase.PAUSED)
    clock = record(d.bus, keys.SIM_CLOCK)
    # recording from here, before the hold begins: a subscription declared after it
    # misses the hold's first poses (tenths of a second of wall time, seconds of sim
    # time at 20x), and the distance they add would go unexplained
    poses, truth = record(d.bus, keys.NAV_POSE), record(d.bus, keys.SIM_TRUTH)

    def sim_time_passes(after_ns: int, s: float) -> bool:
        return clock.until(lambda cs: bool(cs) and cs[-1].sim_ns > after_ns + int(s * 1e9), 30)

    # a pause that met the robot driving lets it brake first (a few seconds at most)
    assert sim_time_passes(paused.stamp_ns, 5.0)
    held = d.state.get()
    assert held is not None and held.phase == MissionPhase.PAUSED
    # a minute of sim time: a running mission would have moved on
    assert sim_time_passes(held.stamp_ns, 60.0)
    now = d.state.get()
    assert now is not None and now.phase == MissionPhase.PAUSED
    assert now.scans_done == held.scans_done
    # distance is measured: the robot truly stands, and the distance grows by what its
    # estimate's speed says over the hold (noise: millimetres, more on a loaded machine
    # where late odometry is refused and the standing updates pause), never by a leg
    still = [t for t in truth if held.stamp_ns <= t.stamp_ns <= now.stamp_ns]
    assert still and max(abs(t.v) for t in still) < 0.02
    hold = [p for p in poses if held.stamp_ns <= p.stamp_ns <= now.stamp_ns]
    noise = sum(
        abs(b.v) * min((b.stamp_ns - a.stamp_ns) / 1e9, 1.0)
        for a, b in itertools.pairwise(hold)
        if b.stamp_ns > a.stamp_ns
    )
    assert abs((now.distance_m - held.distance_m) - noise) < 0.01 + 0.2 * noise, (
        now.distance_m - held.distance_m,
        noise,
    )
    r = subprocess.run([*cli, "resume"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    final = d.wait(lambda x: x.phase in (MissionPhase.DONE, MissionPhase.FAILED))
    assert final.phase == MissionPhase.DONE and final.scans_done == 3
    assert final.distance_m > 5.0, final  # measured from the estimate's speed

    # the log reads back into the report's data
    log = db(d, s.mission)
    steps = log.steps()
    assert [st.status for st in steps] == ["done"] * 3
    for st in steps:
        assert st.file and Path(st.file).exists() and st.attempts == 1
        assert st.mean_x is not None and st.mean_y is not None and st.sd_x is not None
        assert st.sd_x < 0.05
        assert abs(st.mean_x - st.x) < 0.1 and abs(st.mean_y - st.y) < 0.1
        assert st.started_ns is not None and st.ended_ns is not None
        assert st.ended_ns > st.started_ns and st.pitch is not None
    assert log.mission()["state"] == "done"  # type: ignore[index]
    assert any("done" in text for _, _, text in log.events())
    # how each location was reached is in the log
    arrivals = [t for _, _, t in log.events() if ": arrived: " in t]
    assert len(arrivals) >= 3 and all("off the planned pose" in t for t in arrivals), arrivals
    assert sorted(d.scans_started()) == [1, 2, 3]
    # the configuration every service resolved is saved with the mission: what the
    # manifest set, what the defaults filled in, and where each ran
    saved = tomllib.loads((d.runs / s.mission / "config.toml").read_text())
    assert set(saved["services"]) >= {"sim", "gnss", "base", "scanner", "nav", "planner", "mission"}
    assert saved["services"]["mission"]["settle_s"] == 1.0  # the manifest's
    assert saved["services"]["mission"]["scan_retries"] == 2  # the default
    assert saved["services"]["scanner"]["sim_scan_time_s"] == 20.0
    assert saved["machines"]["nav"] == "test"


# a scanner failing scan 2 (both attempts), and the dashboard saving one .rrd per mission
FAILING_SCANNER_AND_VIZ = (
    "scan_retries = 1\n[services.scanner.sim_faults]\nerror_code = 42\nerror_scan_ids = [2]\n"
    '[services.viz]\nsave = "{run_dir}/{mission}/survey.rrd"\n'
)


@pytest.mark.parametrize("deployment", [FAILING_SCANNER_AND_VIZ], indirect=True)
def test_failing_scanner_marks_the_location_failed_and_the_recording_holds_the_rest(
    deployment: Deployment,
) -> None:
    """One survey for two subjects (each survey is most of a minute of CI): the failed
    location, and the dashboard's recording checked with rerun's own tools (it
    verifies and holds the field, route, robot and the clouds of the scans taken)."""
    d = deployment
    assert wait_alive(d.session, {*SERVICES, "viz"}, timeout=60)
    s = d.start()
    final = d.wait(lambda x: x.mission == s.mission and x.phase == MissionPhase.DONE)
    assert final.scans_done == 2 and final.scans_failed == 1
    steps = db(d, s.mission).steps()
    assert [st.status for st in steps] == ["done", "failed", "done"]
    assert steps[1].attempts == 2 and (steps[1].reason or "").startswith("scanner error")
    events = [text for _, _, text in db(d, s.mission).events()]
    assert any("scan 2" in t and "failed" in t for t in events)

    d.close()  # the footer is written when the dashboard stops
    d.up.send_signal(signal.SIGTERM)
    assert d.up.wait(timeout=20) == 0
    path = d.runs / s.mission / "survey.rrd"
    assert path.exists(), sorted(p.name for p in (d.runs / s.mission).iterdir())
    r = rrd.verify(path)
    assert r.returncode == 0, r.stdout + r.stderr
    paths = rrd.entity_paths(path)
    expected = {
        "/field/plots",
        "/field/cells",
        "/field/selected",
        "/route/legs",
        "/robot/estimate",
        "/robot/estimate/body",
        "/robot/trail/0000",
        "/gnss/fix1",
        "/gnss/fix2",
        "/errors/cross_track_m",
        "/mission/log",
        "/scanner/progress",
        "/clouds/scan_001",
        "/clouds/scan_003",
    }
    assert expected <= paths, f"missing {sorted(expected - paths)}; have {sorted(paths)}"
    assert "/clouds/scan_002" not in paths  # the failed location has no cloud
    # what the robot knows: the simulator's truth is the evaluation's to draw
    assert not [p for p in paths if "truth" in p]


def true_stops(d: Deployment, mission: str, truth: list[TruthPose]) -> list[float]:
    """Per scan, the largest distance (m) of the true pose during the scan from the
    planned location: the true pose decides whether a scan is where it belongs."""
    out = []
    for st in db(d, mission).steps():
        assert st.started_ns is not None and st.ended_ns is not None
        during = [t for t in truth if st.started_ns <= t.stamp_ns <= st.ended_ns]
        assert during, f"no truth during scan {st.scan_id}"
        out.append(max(math.hypot(t.x - st.x, t.y - st.y) for t in during))
    return out


def kill(d: Deployment, service: str) -> None:
    """SIGKILL ``service``; the launcher restarts it."""
    pid = next(a.pid for a in wait_alive(d.session, {service}, 10).seen if a.service == service)
    os.kill(pid, signal.SIGKILL)


def test_services_killed_mid_survey_are_restarted_and_the_survey_completes(
    deployment: Deployment,
) -> None:
    """One survey, three kills (one survey each would be minutes of CI; the fault
    campaign kills every service alone, driving and scanning, at the shipped rates):
    nav on the way to scan 2, the mission in the middle of scan 2, the scanner in the
    middle of scan 3."""
    d = deployment
    # the simulated world yields the CPU to the services: a restart's seconds of
    # start-up on a saturated machine once left nav seconds of sim time behind its
    # sensors for the rest of the survey
    pids = {a.service: a.pid for a in wait_alive(d.session, {"sim", "nav"}, 10).seen}
    nice = os.getpriority(os.PRIO_PROCESS, pids["sim"]) - os.getpriority(
        os.PRIO_PROCESS, pids["nav"]
    )
    assert nice == 10
    truth: list[TruthPose] = []
    d.bus.subscribe(keys.SIM_TRUTH, truth.append)
    progress = d.bus.latest(keys.NAV_PROGRESS)
    s = d.start()
    d.wait(lambda x: x.phase == MissionPhase.DRIVING and x.current_scan == 2)
    assert progress.wait_for(  # on the way, not before the route is sent
        lambda p: ".2." in p.route_id and p.state == NavState.DRIVING, timeout=60
    )
    kill(d, "nav")
    d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 2)
    kill(d, "mission")  # it must pick up where it was: no second scan of 2, no gap
    d.wait(
        lambda x: (
            x.mission == s.mission and x.phase == MissionPhase.SCANNING and x.current_scan == 3
        )
    )
    kill(d, "scanner")  # the scan it was taking is lost: taken again
    final = d.wait(
        lambda x: x.mission == s.mission and x.phase == MissionPhase.DONE and x.scans_done == 3
    )
    assert final.scans_failed == 0, final
    steps = db(d, s.mission).steps()
    assert [st.status for st in steps] == ["done"] * 3
    started = d.scans_started()
    assert sorted(set(started)) == [1, 2, 3]
    # the mission's own account of scan 2 says why there was a second attempt
    said = "\n".join(
        ln for ln in d.log.read_text().splitlines() if re.search(r"scan (\S+/)?2\b|\.2\.\d", ln)
    )
    assert started.count(2) == 1, f"scan 2 started {started.count(2)} times: {started}\n{said}"
    off = true_stops(d, s.mission, truth)
    assert max(off) <= 0.05, f"true pose during the scans off the plan by {off} m"
    text = d.log.read_text()
    assert "sending it again" in text  # the restarted navigation got the route, mid-way
    assert "resuming mission" in text
