"""The viz service's Zenoh shell: the live rerun dashboard.

Subscription callbacks only store the newest message of each stream (events and
finished scans are queued, they are rare); a loop at ``rate_hz`` wall time logs what
is new. So the dashboard reads the bus at any rate without ever holding a Zenoh
thread, and a slow viewer or disk costs visual frames, never messages to others: it
subscribes to no control topic and publishes nothing but its health. It shows what
the robot knows; in simulation the true pose is added to the served recording by the
evaluation layer (:mod:`phenorover.eval.truth_view`), never read here. Point clouds
and the cells' view counts are computed on a low-priority worker thread.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import logging
import os
import queue
import threading
from collections.abc import Callable
from typing import Any

from common import keys
from common.clock import SimClock
from common.field import FieldError
from common.field_geojson import field_frame, load_frame
from common.geo import FieldFrame
from common.keys import Topic
from common.messages.mission import MissionEvent, MissionPhase, MissionState
from common.messages.nav import NavProgress, PoseEstimate
from common.messages.plan import PlanResult
from common.messages.scan import ScannerState, ScannerStatus
from common.service import Context
from services.viz import clouds, scene, traits_view
from services.viz.cells import plan_cells
from services.viz.config import VizConfig
from services.viz.fleet_view import FleetView
from services.viz.outputs import Outputs, live_recording_id

# a robot slower than this (m/s, rad/s) stands where its last scan was taken
STILL = 0.01

# streams whose newest message is all the dashboard needs
LATEST: dict[str, Topic[Any]] = {
    "pose": keys.NAV_POSE,
    "progress": keys.NAV_PROGRESS,
    "fix1": keys.GNSS_FIX.at(antenna=1),
    "fix2": keys.GNSS_FIX.at(antenna=2),
    "heading": keys.GNSS_HEADING,
    "lidar": keys.BASE_SCAN,
    "scanner": keys.SCANNER_STATUS,
    "battery": keys.BASE_BATTERY,
    "state": keys.MISSION_STATE,
    "plan": keys.MISSION_PLAN,
}


class VizService:
    def __init__(self, ctx: Context, cfg: VizConfig) -> None:
        self.ctx, self.cfg, self.log = ctx, cfg, ctx.log
        rec_id = live_recording_id(ctx.machine, os.getpid())
        self.out = Outputs(cfg, ctx.run_dir, isinstance(ctx.clock, SimClock), rec_id)
        self.frame = self._frame_of_field(ctx.field)
        self.static: dict[str, scene.Entry] = {e.path: e for e in scene.world(ctx.robot)}
        self.trail = scene.Trail(cfg.trail_step_m)
        self.plan: PlanResult | None = None
        self.state: MissionState | None = None
        self.scanner: ScannerStatus | None = None
        self._last_pose: PoseEstimate | None = None
        self._last_progress: NavProgress | None = None
        self.registered_done = ""
        self.traits = traits_view.TraitsWatch(cfg, self.out.log, self._submit, self.log)
        self.failed: set[str] = set()
        self._lock = threading.Lock()
        self._new: dict[str, Any] = {}
        self._events: collections.deque[MissionEvent] = collections.deque(maxlen=1000)
        self._done: collections.deque[ScannerStatus] = collections.deque(maxlen=100)
        self._done_seen: set[tuple[int, str]] = set()
        self._scan_poses: dict[int, PoseEstimate] = {}
        self._jobs: queue.Queue[Callable[[], None] | None] = queue.Queue(maxsize=64)
        self.superseded = 0  # messages replaced by a newer one before being drawn
        self.drawn = 0  # the newest messages drawn, in the heartbeat: the view keeps up
        ctx.bus.report("messages_drawn", lambda: self.drawn)
        for name, topic in LATEST.items():
            ctx.bus.subscribe(topic, functools.partial(self._put, name))
        ctx.bus.subscribe(keys.MISSION_EVENT, self._on_event)
        # robots sharing the field (none: nothing), each under fleet/<namespace>/
        self.fleet = FleetView(ctx.bus, cfg.robots, ctx.robot, self.out.log, self._set_static)
        # the servers listen before the service is alive (after build()), so a client
        # that sees it alive can connect; run() closes them
        self.out.start()

    # --- bus callbacks (Zenoh threads: store and return) ---
    def _put(self, name: str, msg: Any) -> None:
        with self._lock:
            self.superseded += name in self._new
            self._new[name] = msg
            if (
                isinstance(msg, ScannerStatus)
                and msg.state == ScannerState.DONE
                and msg.file
                and (msg.scan_id, msg.file) not in self._done_seen
            ):
                self._done_seen.add((msg.scan_id, msg.file))
                self._done.append(msg)

    def _on_event(self, e: MissionEvent) -> None:
        with self._lock:
            self._events.append(e)

    def _frame_of_field(self, source: str) -> FieldFrame | None:
        try:
            return load_frame(source, self.ctx.clock)
        except (FieldError, ValueError) as exc:
            self.log.warning("viz: no georeference for GNSS fixes until a plan arrives: %s", exc)
            return None

    # --- the logging loop ---
    def run(self, stop: threading.Event) -> None:
        with contextlib.suppress(OSError):
            os.nice(5)  # the robot's control processes come first on a shared machine
        worker = threading.Thread(target=self._work, daemon=True, name="viz-worker")
        worker.start()
        try:
            for rec in self.out.streams():
                # a copy: the worker thread adds the field's cells meanwhile
                self.out.log_static(rec, list(self.static.values()))
            while not stop.wait(1.0 / self.cfg.rate_hz):
                self.tick()
        finally:
            # what arrived since the last tick (the last scan's DONE, when the survey
            # ended just before the deployment was stopped) is still drawn; the worker
            # gets until well inside the launcher's 4 s grace, so the footer is written
            self._guarded("last tick", self.tick)
            self._jobs.put(None)
            worker.join(timeout=3.0)
            self.out.close()
            self.log.info("viz: %d messages superseded before being drawn", self.superseded)

    def tick(self) -> None:
        """Log everything that arrived since the last tick."""
        with self._lock:
            new, self._new = self._new, {}
            events = list(self._events)
            self._events.clear()
            done = list(self._done)
            self._done.clear()
            self.drawn += len(new)
        # the plan and the mission first: a new mission's file must exist before the
        # data of the same tick is logged
        for name in ("plan", "state", *[k for k in LATEST if k not in ("plan", "state")]):
            if name in new:
                self._guarded(name, functools.partial(self._handle, name, new[name]))
        for e in events:
            self._guarded("event", functools.partial(self._log_event, e))
        for st in done:
            self._guarded("scan", functools.partial(self._queue_scan, st))
        self._guarded("fleet", self.fleet.tick)
        self._guarded("registered", self._check_registered)
        self._guarded("traits", lambda: self.traits.poll(self.ctx.run_dir, self.state))

    def _log_event(self, e: MissionEvent) -> None:
        self.out.log(e.stamp_ns, [scene.event_entry(e)])

    def _guarded(self, what: str, fn: Callable[[], None]) -> None:
        """A message the scene cannot draw is reported once per kind, not fatal."""
        try:
            fn()
        except Exception as exc:
            if what not in self.failed:
                self.failed.add(what)
                self.log.warning("viz: cannot show %s: %s", what, exc, exc_info=True)

    def _handle(self, name: str, m: Any) -> None:
        log = self.out.log
        if name == "plan":
            self._on_plan(m)
        elif name == "state":
            self._on_state(m)
        elif name == "pose":
            prog = self._last_progress
            cte = prog.cross_track if prog is not None else 0.0
            log(m.stamp_ns, [scene.pose("robot/estimate", m.x, m.y, m.z, m.yaw)])
            log(m.stamp_ns, self.trail.add(m.x, m.y, cte))
            self._last_pose = m
        elif name == "progress":
            self._last_progress = m
            log(m.stamp_ns, scene.progress_entries(m))
        elif name in ("fix1", "fix2") and self.frame is not None:
            log(m.stamp_ns, [scene.fix_entry(m, self.frame)])
        elif name == "heading" and self._last_pose is not None:
            log(m.stamp_ns, [scene.heading_entry(m, self._last_pose.x, self._last_pose.y)])
        elif name == "lidar":
            log(m.stamp_ns, [scene.lidar_entry(m, self.ctx.robot.lidar)])
        elif name == "battery":
            log(m.stamp_ns, [scene.battery_entry(m)])
        elif name == "scanner":
            log(m.stamp_ns, scene.scanner_entries(self.scanner, m))
            self.scanner = m
            if m.state == ScannerState.SCANNING and self._last_pose is not None:
                self._scan_poses[m.scan_id] = self._last_pose  # where it is being taken

    def _set_static(self, entries: list[scene.Entry]) -> None:
        for e in entries:
            self.static[e.path] = e
        for rec in self.out.streams():
            self.out.log_static(rec, entries)

    def _on_plan(self, plan: PlanResult) -> None:
        if plan == self.plan:
            return
        self.plan = plan
        if plan.layout.georeferenced:
            self.frame = field_frame(plan.layout)
        self._set_static(scene.plan_entries(plan))
        self._submit(lambda: self._cells(plan))

    def _cells(self, plan: PlanResult) -> None:
        field, views, why = plan_cells(plan)
        if plan is self.plan:
            self.traits.field = field  # the traits' plots are this plan's
        if views is None or field is None:
            self.log.info("viz: %s", why)
        elif plan is self.plan:  # not a plan a newer one replaced meanwhile
            self._set_static([scene.cell_entry(field, views)])

    def _on_state(self, s: MissionState) -> None:
        if s.in_progress and self.out.open_mission(s.mission):
            rec = self.out.mission_stream
            if rec is not None:
                # a copy: the worker thread adds the field's cells meanwhile
                self.out.log_static(rec, list(self.static.values()))
        self.out.log(s.stamp_ns, scene.state_entries(self.state, s))
        self.state = s

    def _queue_scan(self, st: ScannerStatus) -> None:
        """Draw a finished scan where it was taken: the pose seen while it was being
        taken, else (this dashboard started during or after it: the scanner repeats
        its DONE until the next scan) the robot's if it still stands there."""
        pose = self._scan_poses.pop(st.scan_id, None)
        last = self._last_pose
        if pose is None and last is not None and abs(last.v) < STILL and abs(last.w) < STILL:
            pose = last
        if pose is None:
            raise ValueError(
                f"scan {st.scan_id} was not seen being taken and the robot has moved on: "
                "not drawn (its place is in the mission log)"
            )
        mount = self.ctx.robot.scanner

        def job() -> None:
            pts = clouds.scan_in_field(
                st.file, pose, st.pitch, st.roll, mount, self.cfg.scan_points
            )
            self.out.log(st.stamp_ns, [scene.cloud_entry(f"clouds/scan_{st.scan_id:03d}", pts)])

        self._submit(job)

    def _check_registered(self) -> None:
        s = self.state
        if s is None or s.phase != MissionPhase.DONE or self.registered_done == s.mission:
            return
        found = clouds.find_registered(self.ctx.run_dir / s.mission, self.cfg.registered_files)
        if found is None:
            return
        self.registered_done = s.mission
        stamp = s.stamp_ns

        def job() -> None:
            pts = clouds.registered(found, self.cfg.registered_points)
            self.out.log(stamp, [scene.cloud_entry("clouds/registered", pts)])
            self.log.info("viz: registered cloud %s shown (%d points)", found, len(pts))

        self._submit(job)

    # --- the worker ---
    def _submit(self, job: Callable[[], None]) -> None:
        try:
            self._jobs.put_nowait(job)
        except queue.Full:
            self.log.warning("viz: worker busy, a cloud is not shown")

    def _work(self) -> None:
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), 15)
        while (job := self._jobs.get()) is not None:
            self._guarded("cloud", job)


def build(ctx: Context, cfg: VizConfig) -> VizService:
    logging.getLogger("rerun").setLevel(logging.WARNING)
    return VizService(ctx, cfg)
