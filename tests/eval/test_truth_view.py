"""The simulator's truth beside the dashboard's estimate: the evaluation's overlay logs
into the very recording the dashboard serves, follows a restarted dashboard, and is
started beside a simulated deployment only when its dashboard serves."""

from __future__ import annotations

import re
import subprocess
import time
from pathlib import Path
from typing import Any, cast

import rerun as rr

from common import keys
from common.client import wait_alive
from common.config import Manifest, load_manifest
from common.messages.nav import PoseEstimate
from common.messages.sim import TruthPose
from common.robot import default_robot
from common.transport import Bus
from phenorover.eval.truth_view import TruthView, beside, served
from services.viz.config import VizConfig
from services.viz.outputs import live_recording_id, local_url
from tests.conftest import FakeBus, Procs, free_port
from tests.viz import rrd


def recordings(path: Path) -> set[str]:
    """The recording ids (not blueprints) an .rrd holds, from ``rerun rrd stats``."""
    r = subprocess.run(
        [str(rrd.RERUN), "rrd", "stats", str(path)], capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr
    return set(re.findall(r'StoreId\(Recording, "[^"]*", "([^"]*)"\)', r.stdout))


def test_the_truth_lands_in_the_recording_the_dashboard_serves(
    router_endpoint: str, client_bus: Bus, procs: Procs, tmp_path: Path
) -> None:
    """The dashboard as the launcher runs it (its own process, its liveliness token),
    a viewer connected to its server, and the overlay beside it: the viewer gets one
    recording holding the dashboard's estimate and the overlay's truth."""
    cfg = VizConfig(serve=True, bind="127.0.0.1", grpc_port=free_port(), web_port=0)
    opts = [f"grpc_port={cfg.grpc_port}", "web_port=0", 'bind="127.0.0.1"']
    sets = [x for o in opts for x in ("--set", o)]
    viz = procs.service("services.viz", router_endpoint, "--serve", *sets, log=tmp_path / "viz.log")
    assert wait_alive(client_bus.session, {"viz"}, timeout=30), (tmp_path / "viz.log").read_text()
    out = tmp_path / "viewer.rrd"
    # a viewer: rerun's CLI writes what the server sends it until the server goes
    viewer = subprocess.Popen(
        [str(rrd.RERUN), "--connect", local_url(cfg), "--save", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    view = TruthView(client_bus, cfg, default_robot(), "test", sim_time=False)
    try:
        truth = client_bus.publisher(keys.SIM_TRUTH)
        poses = client_bus.publisher(keys.NAV_POSE)
        health = client_bus.latest(keys.HEALTH.at(service="viz"))
        assert view.wait_news(20), "the overlay never saw the dashboard's token"
        view.tick()
        assert view.rec is not None and view.dashboard == viz.pid
        assert poses.wait_matched(10), "the dashboard never subscribed to the estimate"
        now = time.time_ns()
        truth.put(TruthPose(stamp_ns=now, x=0.1, y=2.0, z=0.0, yaw=0.1))
        poses.put(PoseEstimate(stamp_ns=now, x=0.15, y=2.0, yaw=0.1))
        assert view.wait_news(10), "the truth never reached the overlay"
        view.tick()
        # the dashboard's heartbeat counts what it has drawn: the estimate, once drawn
        beat = health.wait_for(lambda h: h.counters.get("messages_drawn", 0) >= 1, timeout=20)
        assert beat is not None, "the dashboard never drew the estimate"
    finally:
        view.close()
        viz.terminate()
        assert viz.wait(timeout=10) == 0
        try:
            assert viewer.wait(timeout=20) == 0  # it stops when the server does
        finally:
            viewer.kill()
    assert recordings(out) == {live_recording_id("test", viz.pid)}
    paths = rrd.entity_paths(out)
    assert {"/robot/estimate", "/robot/truth", "/robot/truth/body"} <= paths


def test_each_robots_truth_is_followed_into_a_restarted_dashboards_recording() -> None:
    bus = FakeBus()
    cfg = VizConfig(serve=True, bind="127.0.0.1", grpc_port=free_port(), robots=["r1", "r2"])
    # a server to connect to (for the rest of this process: rerun keeps it)
    server = rr.RecordingStream("server")
    server.set_sinks(rr.GrpcServerSink(cfg.bind, cfg.grpc_port))
    view = TruthView(cast(Bus, bus), cfg, default_robot(), "base", sim_time=True)
    assert {keys.SIM_TRUTH.within(ns).key for ns in ("r1", "r2")} <= set(bus.subs)
    (watch,) = bus.watched.values()
    try:
        view.tick()
        assert view.rec is None  # no dashboard alive: nothing to log into
        watch("phenorover/alive/base/viz/100/1", True)
        view.tick()
        assert view.rec is not None
        assert view.rec.get_recording_id() == live_recording_id("base", 100)
        watch("phenorover/alive/base/viz/100/1", False)
        watch("phenorover/alive/base/viz/200/2", True)
        view.tick()
        assert view.rec is not None
        assert view.rec.get_recording_id() == live_recording_id("base", 200)
        watch("phenorover/alive/base/viz/200/2", False)
        view.tick()
        assert view.rec is None
    finally:
        view.close()


def manifest(viz: dict[str, Any] | None) -> Manifest:
    return Manifest(machine="sim", clock="sim", services={"viz": viz} if viz is not None else {})


def test_the_overlay_runs_only_beside_a_served_dashboard(
    router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    assert served(manifest(None)) is None
    assert served(manifest({"save": "x.rrd"})) is None
    assert served(manifest({"serve": True})) is not None
    with beside(tmp_path / "none.toml", manifest({"save": "x.rrd"})) as proc:
        assert proc is None
    # served: the overlay as a child process on the deployment's router, waiting for
    # a dashboard, and stopped when the block ends
    path = tmp_path / "sim.toml"
    path.write_text(
        f'machine = "sim"\nclock = "sim"\n[zenoh]\nlisten = ["{router_endpoint}"]\n'
        f"[services.viz]\nserve = true\ngrpc_port = {free_port()}\n"
    )
    with beside(path, load_manifest(path)) as proc:
        assert proc is not None
        # up on the router: it subscribes to the truth (a bad manifest or no router
        # would have made it exit, 2, instead)
        assert client_bus.publisher(keys.SIM_TRUTH).wait_matched(timeout=30)
        assert proc.poll() is None
    assert proc.poll() == 0  # SIGTERM: a clean stop
