"""A simulator killed with SIGKILL and started again by the same parent carries on
with its world: ``sim/clock`` continues from about where it stopped (not 0) and the
robot's true pose from where it was; stopped with SIGTERM it leaves nothing to
resume; with ``resume = false`` it starts afresh."""

from __future__ import annotations

import math
import signal
import subprocess
from pathlib import Path

import msgspec
import pytest

from common import keys
from common.client import wait_alive
from common.clock import NS
from common.messages.sim import SimClock, SimWheelCommand, TruthPose
from common.transport import Bus
from services.sim.snapshot import Snapshot, snapshot_path
from tests.conftest import REPO, Procs

TINY = REPO / "tests" / "data" / "tiny.toml"
RTF, SNAPSHOT_S = 10.0, 0.2


def manifest(tmp: Path, resume: bool = True) -> Path:
    m = tmp / "m.toml"
    m.write_text(f"""machine = "test"
clock = "sim"
field = "{TINY}"
run_dir = "{tmp / "runs"}"
[services.sim]
real_time_factor = {RTF}
snapshot_s = {SNAPSHOT_S}
resume = {str(resume).lower()}
# one command keeps the robot turning: the test does not have to keep publishing
motor_timeout_s = 100000.0
""")
    return m


class Sim:
    def __init__(self, procs: Procs, endpoint: str, bus: Bus, tmp: Path, resume: bool) -> None:
        self.procs, self.endpoint, self.bus, self.tmp = procs, endpoint, bus, tmp
        self.manifest = manifest(tmp, resume)
        self.starts = 0

    def start(self) -> subprocess.Popen[bytes]:
        """Start the simulator; ``first_clock``/``first_truth``: its first messages seen."""
        self.starts += 1
        # fresh subscriptions, before the process: nothing of the previous one is in them
        self.clock = self.bus.latest(keys.SIM_CLOCK)
        self.truth = self.bus.latest(keys.SIM_TRUTH)
        log = self.tmp / f"sim{self.starts}.log"
        args = ("--manifest", str(self.manifest))
        p = self.procs.service("services.sim", self.endpoint, *args, log=log)
        clock, truth = (
            self.clock.wait_for(lambda c: True, 30),
            self.truth.wait_for(lambda t: True, 30),
        )
        assert clock is not None and truth is not None, "the simulator publishes nothing"
        self.first_clock: SimClock = clock
        self.first_truth: TruthPose = truth
        return p


@pytest.fixture
def sim(procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path) -> Sim:
    return Sim(procs, router_endpoint, client_bus, tmp_path, resume=True)


def test_killed_simulator_continues_its_clock_and_robot(sim: Sim, client_bus: Bus) -> None:
    p = sim.start()
    wheels = client_bus.publisher(keys.SIM_WHEELS)
    assert wheels.wait_matched(timeout=10)
    wheels.put(SimWheelCommand(stamp_ns=0, v=0.0, w=0.5))  # turn in place
    turned = sim.truth.wait_for(lambda t: t.stamp_ns > 20 * NS and abs(t.w) > 0.3, timeout=30)
    assert turned is not None, "the robot did not turn"
    # 20 s of sim time turning (2 s of wall time at 10x): ten snapshots' worth
    last = sim.clock.wait_for(lambda c: c.sim_ns > turned.stamp_ns + 20 * NS, timeout=30)
    assert last is not None
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=10)
    killed_at = sim.clock.get()
    assert killed_at is not None
    snap = msgspec.json.decode(snapshot_path(sim.tmp / "runs").read_bytes(), type=Snapshot)
    # saved as the world went on (every 0.2 s of wall time; a loaded machine may be
    # late by some), so the one left is of the robot turning, not of its start
    assert turned.stamp_ns <= snap.sim_ns <= killed_at.sim_ns, (turned, snap.sim_ns, killed_at)

    sim.start()
    # the clock goes on from the snapshot, not from 0 (the first messages may be missed
    # while the subscription reaches the new process: a few seconds of sim time) ...
    resumed = sim.first_clock
    assert snap.sim_ns <= resumed.sim_ns < snap.sim_ns + 10 * NS, (resumed, snap.sim_ns)
    # ... and so does the robot, from where the snapshot had it, still turning down
    robot, pose = snap.robot, sim.first_truth
    assert abs(robot["w"]) > 0.1, robot  # turning (at 0.5 rad/s asked; slip varies it)
    dt = (pose.stamp_ns - snap.sim_ns) / NS
    assert math.hypot(pose.x - robot["x"], pose.y - robot["y"]) < 0.05 + 0.05 * dt
    assert abs(math.remainder(pose.yaw - robot["yaw"], math.tau)) <= 0.5 * dt + 0.05
    text = (sim.tmp / "sim2.log").read_text()
    assert "continuing the world" in text, text[-2000:]
    # told to stop (the deployment ends), it leaves a closed snapshot: nothing to resume
    p2 = sim.procs.procs[-1]
    p2.send_signal(signal.SIGTERM)
    assert p2.wait(timeout=10) == 0
    final = msgspec.json.decode(snapshot_path(sim.tmp / "runs").read_bytes(), type=Snapshot)
    assert final.closed and final.sim_ns > snap.sim_ns


def test_without_resume_a_restarted_simulator_starts_afresh(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    sim = Sim(procs, router_endpoint, client_bus, tmp_path, resume=False)
    p = sim.start()
    assert sim.clock.wait_for(lambda c: c.sim_ns > 10 * NS, timeout=30)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=10)
    assert snapshot_path(tmp_path / "runs").exists()
    sim.start()
    assert sim.first_clock.sim_ns < 5 * NS
    assert wait_alive(client_bus.session, {"sim"}, timeout=10)
