"""The simulator's true pose on the live dashboard, beside the robot's estimate.

An evaluation-layer process: it subscribes to ``sim/truth/pose`` (the robot's own, and
each robot's of ``[services.viz] robots`` under its namespace) and logs
``robot/truth`` (with a grey body box) and ``fleet/<namespace>/truth`` into the
recording the viz service serves. The dashboard itself shows only what the robot
knows: simulation truth is read by the evaluation and nowhere in the product.

Rerun shows the data of one application id and recording id as one recording, from
however many processes it comes. The dashboard's live recording id is
:func:`services.viz.outputs.live_recording_id` of the machine and pid in its
liveliness token (``alive/<machine>/viz/<pid>/<since_ns>``), so this process follows
that token: when the dashboard restarts (a new pid, a new recording) it opens a stream
into the new recording and logs the body again.

``python -m phenorover.eval.truth_view --manifest deploy/sim.toml`` beside a running
simulated deployment whose dashboard serves (``[services.viz] serve = true``);
``phenorover sim`` runs it while its deployment runs (:func:`beside`).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import logging
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path

import rerun as rr

from common import keys
from common.client import DEFAULT_MANIFEST, add_connection_arguments, connect_or_explain
from common.config import ConfigError, Manifest, decode_section, load_manifest
from common.messages.sim import TruthPose
from common.process import die_with_parent, stop_process
from common.robot import Robot, load_robot
from common.service_args import setup_logging
from common.status import parse_token
from common.transport import Bus
from services.viz import scene
from services.viz.config import VizConfig
from services.viz.outputs import APP_ID, live_recording_id, local_url, set_time

log = logging.getLogger("truth_view")

MODULE = "phenorover.eval.truth_view"  # run as a program by :func:`beside`

TRUTH_BODY = (*scene.GREY, 90)  # translucent: the estimate's blue body shows through
FLUSH_S = 2.0  # on stop: the rest of the stream to a dashboard that is alive


class TruthView:
    """Truth poses from ``bus``, logged on :meth:`tick` into the recording of the
    dashboard alive on ``machine`` (none alive: they are dropped until one is)."""

    def __init__(
        self, bus: Bus, cfg: VizConfig, robot: Robot, machine: str, sim_time: bool
    ) -> None:
        self.cfg, self.robot, self.machine, self.sim_time = cfg, robot, machine, sim_time
        self.url = local_url(cfg)
        self.rec: rr.RecordingStream | None = None
        self.dashboard: int | None = None  # the pid of the dashboard we log into
        self._lock = threading.Lock()
        self._news = threading.Condition(self._lock)  # a truth or a token arrived
        self._new: dict[str, TruthPose] = {}
        self._alive: int | None = None
        bus.subscribe(keys.SIM_TRUTH, functools.partial(self._put, "robot/truth"))
        for ns in cfg.robots:
            on_truth = functools.partial(self._put, f"fleet/{ns}/truth")
            bus.subscribe(keys.SIM_TRUTH.within(ns), on_truth)
        token = keys.ALIVE.format(machine=machine, service="viz", pid="*", since_ns="*")
        bus.watch(token, self._on_alive)

    # --- bus callbacks (Zenoh threads: store and return) ---
    def _put(self, path: str, msg: TruthPose) -> None:
        with self._lock:
            self._new[path] = msg
            self._news.notify_all()

    def _on_alive(self, key: str, alive: bool) -> None:
        token = parse_token(key)
        if token is None:
            return
        with self._lock:
            if alive:
                self._alive = token.pid
            elif self._alive == token.pid:
                self._alive = None
            self._news.notify_all()

    # --- the logging loop ---
    def wait_news(self, timeout: float) -> bool:
        """Until a truth has arrived since the last :meth:`tick` or the dashboard to
        follow has changed (True), or ``timeout`` seconds (False)."""
        with self._news:
            return self._news.wait_for(
                lambda: bool(self._new) or self._alive != self.dashboard, timeout
            )

    def tick(self) -> None:
        """Follow the dashboard, then log the newest truth of each robot."""
        with self._lock:
            new, self._new = self._new, {}
            alive = self._alive
        if alive != self.dashboard:
            self._follow(alive)
        if self.rec is None:
            return
        for path, m in new.items():
            set_time(self.rec, m.stamp_ns, self.sim_time)
            self.rec.log(path, scene.pose(path, m.x, m.y, m.z, m.yaw).item)

    def _follow(self, pid: int | None) -> None:
        # the dashboard logged into so far is gone, and its server with it: nothing to flush
        self._drop(flush=False)
        self.dashboard = pid
        if pid is None:
            log.info("truth_view: no dashboard alive on %s: waiting for one", self.machine)
            return
        rec_id = live_recording_id(self.machine, pid)
        # no properties and no blueprint: the recording's are the dashboard's
        self.rec = rr.RecordingStream(APP_ID, recording_id=rec_id, send_properties=False)
        self.rec.set_sinks(rr.GrpcSink(self.url))
        entry = scene.body("robot/truth/body", self.robot, TRUTH_BODY, solid=True)
        self.rec.log(entry.path, entry.item, static=True)
        log.info("truth_view: the true pose into recording %s at %s", rec_id, self.url)

    def _drop(self, flush: bool) -> None:
        rec, self.rec = self.rec, None
        if rec is None:
            return
        if flush:
            # rerun raises when the server cannot be reached within the timeout
            with contextlib.suppress(RuntimeError):
                rec.flush(timeout_sec=FLUSH_S)
        rec.disconnect()

    def close(self) -> None:
        """Send what is logged (for up to ``FLUSH_S``) and close the stream."""
        self._drop(flush=True)


def served(manifest: Manifest) -> VizConfig | None:
    """The dashboard's options when ``manifest`` runs one that serves, else None.
    Raises ConfigError on a bad ``[services.viz]``."""
    section = manifest.services.get("viz")
    if section is None:
        return None
    cfg = decode_section(section, VizConfig, "[services.viz]")
    return cfg if cfg.serve else None


@contextlib.contextmanager
def beside(manifest_path: Path, manifest: Manifest) -> Iterator[subprocess.Popen[bytes] | None]:
    """This module as a child process while the block runs, when ``manifest`` runs a
    dashboard that serves (else nothing: None); stopped (SIGTERM) when the block ends,
    and by the kernel if this process dies first."""
    if served(manifest) is None:
        yield None
        return
    cmd = [sys.executable, "-m", MODULE, "--manifest", str(manifest_path)]
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, preexec_fn=die_with_parent)
    try:
        yield proc
    finally:
        stop_process(proc, 5.0)


def main(argv: Sequence[str] | None = None) -> int:
    """Run until SIGTERM or SIGINT: 0; 2 when the manifest runs no served dashboard or
    the deployment cannot be reached (one line on stderr)."""
    p = argparse.ArgumentParser(prog="python -m phenorover.eval.truth_view", description=__doc__)
    add_connection_arguments(p)
    p.add_argument("--log-level", default="info")
    args = p.parse_args(argv)
    setup_logging(args.log_level)
    path = args.manifest or DEFAULT_MANIFEST
    try:
        manifest = load_manifest(path)
        cfg = served(manifest)
        robot = load_robot(manifest.robot)
    except ConfigError as exc:
        print(f"truth_view: {exc}", file=sys.stderr)
        return 2
    if cfg is None:
        print(f"truth_view: {path} serves no dashboard ([services.viz] serve)", file=sys.stderr)
        return 2
    session = connect_or_explain("truth_view", path, args.connect)
    if session is None:
        return 2
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    bus = Bus(session, "truth_view", namespace=manifest.namespace)
    view = TruthView(bus, cfg, robot, manifest.machine, manifest.clock == "sim")
    period = 1.0 / cfg.rate_hz
    try:
        while not stop.is_set():
            if view.wait_news(period):  # at most rate_hz ticks, none without news
                view.tick()
                stop.wait(period)
    finally:
        view.close()
        bus.close()
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
