"""Whole surveys of a small field with every service as its own process under
``phenorover up``: complete, killed mid-scan and resumed, a failing scanner, pause and
resume from a second process, a malformed plan."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from common import keys
from common.cli import wait_alive
from common.config import zenoh_config
from common.messages.mission import MissionPhase, MissionStart, MissionState
from common.transport import Bus, RpcError
from services.mission.log import MissionLog
from tests.conftest import REPO, Procs, free_port

TINY = REPO / "tests" / "data" / "tiny.toml"
SERVICES = {"sim", "gnss", "base", "scanner", "nav", "planner", "mission"}


class Deployment:
    def __init__(self, procs: Procs, tmp: Path, extra: str = "") -> None:
        self.tmp, self.port = tmp, free_port()
        self.runs = tmp / "runs"
        manifest = tmp / "m.toml"
        manifest.write_text(f"""machine = "test"
clock = "sim"
field = "{TINY}"
run_dir = "{self.runs}"
[zenoh]
listen = ["tcp/127.0.0.1:{self.port}"]
[services.sim]
real_time_factor = 20.0
[services.gnss]
[services.base]
[services.scanner]
storage_dir = "{tmp / "card"}"
sim_scan_time_s = 20.0
render_step_deg = 1.0
status_timeout_s = 40.0  # sim seconds: 2 s of wall time at 20x on two busy cores
[services.nav]
[services.planner]
[services.mission]
settle_s = 1.0
{extra}""")
        self.log = tmp / "up.log"
        self.up = procs.start("-m", "common.cli", "up", str(manifest), log=self.log)
        self.session = zenoh.open(zenoh_config("client", [], [f"tcp/127.0.0.1:{self.port}"]))
        self.bus = Bus(self.session, "test")
        assert wait_alive(self.session, SERVICES, timeout=60), "deployment did not come up"
        self.state = self.bus.latest(keys.MISSION_STATE)

    def start(self, **kw: str) -> MissionState:
        deadline = time.monotonic() + 60
        while True:
            try:
                return self.bus.call(
                    keys.MISSION_CMD, MissionStart(field=str(TINY), **kw), timeout=120
                )
            except RpcError as exc:
                if "no reply" not in str(exc) or time.monotonic() > deadline:
                    raise

    def wait(self, pred: object, timeout: float = 240) -> MissionState:
        s = self.state.wait_for(pred, timeout=timeout)  # type: ignore[arg-type]
        assert s is not None, f"mission state not reached; last {self.state.get()}"
        return s

    def close(self) -> None:
        self.bus.close()
        self.session.close()

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
    bad = d.tmp / "bad.json"
    bad.write_text('{"field": "tiny"}')
    with pytest.raises(RpcError, match=r"MissionStart\.plan_file: .*bad\.json"):
        d.start(plan_file=str(bad))
    assert not d.runs.exists() or not list(d.runs.iterdir()), "a malformed plan started something"

    s = d.start()
    assert s.scans_total == 3
    d.wait(lambda x: x.mission == s.mission and x.phase == MissionPhase.SCANNING)
    cli = [sys.executable, "-m", "common.cli", "mission", "--connect", f"tcp/127.0.0.1:{d.port}"]
    r = subprocess.run([*cli, "pause"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "paused" in r.stdout, r.stderr
    held = d.wait(lambda x: x.phase == MissionPhase.PAUSED)
    time.sleep(3.0)  # 60 s of sim time at 20x: a running mission would have moved on
    now = d.state.get()
    assert now is not None and now.phase == MissionPhase.PAUSED
    assert now.scans_done == held.scans_done and now.distance_m == held.distance_m
    r = subprocess.run([*cli, "resume"], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    final = d.wait(lambda x: x.phase in (MissionPhase.DONE, MissionPhase.FAILED))
    assert final.phase == MissionPhase.DONE and final.scans_done == 3

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
    assert sorted(d.scans_started()) == [1, 2, 3]


def test_mission_killed_mid_scan_resumes_without_duplicate_or_gap(
    deployment: Deployment,
) -> None:
    d = deployment
    s = d.start()
    d.wait(lambda x: x.phase == MissionPhase.SCANNING and x.current_scan == 2)
    pid = next(a.pid for a in wait_alive(d.session, {"mission"}, 10) if a.service == "mission")
    os.kill(pid, signal.SIGKILL)  # the launcher restarts it; it must pick up where it was
    final = d.wait(
        lambda x: x.mission == s.mission and x.phase == MissionPhase.DONE and x.scans_done == 3
    )
    assert final.scans_failed == 0
    steps = db(d, s.mission).steps()
    assert [st.status for st in steps] == ["done"] * 3
    started = d.scans_started()
    assert sorted(set(started)) == [1, 2, 3]
    assert started.count(2) == 1, f"scan 2 started {started.count(2)} times: {started}"
    assert "resuming mission" in d.log.read_text()


@pytest.mark.parametrize(
    "deployment",
    ["scan_retries = 1\n[services.scanner.sim_faults]\nerror_code = 42\nerror_scan_ids = [2]\n"],
    indirect=True,
)
def test_failing_scanner_marks_the_location_failed_and_goes_on(deployment: Deployment) -> None:
    d = deployment
    s = d.start()
    final = d.wait(lambda x: x.mission == s.mission and x.phase == MissionPhase.DONE)
    assert final.scans_done == 2 and final.scans_failed == 1
    steps = db(d, s.mission).steps()
    assert [st.status for st in steps] == ["done", "failed", "done"]
    assert steps[1].attempts == 2 and steps[1].reason == "scanner error"
    events = [text for _, _, text in db(d, s.mission).events()]
    assert any("scan 2" in t and "failed" in t for t in events)
