"""The mission supervisor's Zenoh shell: runs a survey with nobody in the loop.

For each scan location in tour order: send the legs to navigation, wait for
arrival, wait until the robot is still and localized, scan over the scanner service,
record the scan and the pose statistics over it in the mission log, and go on;
finally return to the Origin. Every step is committed to ``mission.db`` before the
next begins; a restarted service resumes at the first unfinished location and never
scans a location twice (a scan interrupted by a crash is taken from the scanner if
it finished, redone only if it did not).
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path

import msgspec

from common import clock as clk
from common import keys
from common.messages.mission import (
    MissionAbort,
    MissionCommand,
    MissionEvent,
    MissionPause,
    MissionPhase,
    MissionResume,
    MissionStart,
    MissionState,
    MissionStatusQuery,
)
from common.messages.nav import CancelRoute, FollowRoute, NavState, PoseEstimate
from common.messages.plan import PlanRequest, PlanResult
from common.messages.scan import ScannerState, StartScan, StopScan
from common.service import Context
from common.transport import RequestError, RpcError
from services.mission.config import MissionConfig
from services.mission.log import MissionLog
from services.mission.plan import Segment, segments
from services.register.hook import REGISTERING, RegistrationJob

# wall seconds between copies of the plan on mission/plan, for subscribers joining late
PLAN_REPUBLISH_S = 5.0


class Aborted(Exception):
    pass


def pose_stats(poses: list[PoseEstimate]) -> dict[str, float]:
    """Mean and SD of x, y, z and heading (circular) over a scan."""
    n = max(len(poses), 1)
    out: dict[str, float] = {}
    for k in ("x", "y", "z"):
        v = [getattr(p, k) for p in poses] or [math.nan]
        m = sum(v) / n
        out[f"mean_{k}"] = m
        out[f"sd_{k}"] = math.sqrt(sum((a - m) ** 2 for a in v) / n)
    c = sum(math.cos(p.yaw) for p in poses) / n
    s = sum(math.sin(p.yaw) for p in poses) / n
    out["mean_yaw"] = math.atan2(s, c)
    out["sd_yaw"] = math.sqrt(max(0.0, -2.0 * math.log(max(math.hypot(c, s), 1e-12))))
    return out


class MissionService:
    def __init__(self, ctx: Context, cfg: MissionConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        bus = ctx.bus
        self.pose = bus.latest(keys.NAV_POSE)
        self.progress = bus.latest(keys.NAV_PROGRESS)
        self.scanner = bus.latest(keys.SCANNER_STATUS)
        self.state_pub = bus.publisher(keys.MISSION_STATE)
        self.event_pub = bus.publisher(keys.MISSION_EVENT)
        self.plan_pub = bus.publisher(keys.MISSION_PLAN)
        self.plan: PlanResult | None = None
        self._plan_sent = 0.0
        self._lock = threading.Lock()
        self._collect: list[PoseEstimate] | None = None
        bus.subscribe(keys.NAV_POSE, self._on_pose)
        self.log: MissionLog | None = None
        self.mission = ""
        self.phase = MissionPhase.IDLE
        self.detail = ""
        self.current = 0
        self.distance = 0.0
        self._paused = threading.Event()
        self._abort = threading.Event()
        self._worker: threading.Thread | None = None
        self._registration: RegistrationJob | None = None
        self._stop = threading.Event()
        bus.serve(keys.MISSION_CMD, self.handle)

    # --- bus inputs ---
    def _on_pose(self, p: PoseEstimate) -> None:
        with self._lock:
            if self._collect is not None:
                self._collect.append(p)

    def event(self, level: str, text: str) -> None:
        now = self.ctx.clock.now_ns()
        getattr(self.ctx.log, "warning" if level == "warning" else level)("%s", text)
        if self.log is not None:
            self.log.event(now, level, text)
        self.event_pub.put(MissionEvent(stamp_ns=now, mission=self.mission, level=level, text=text))

    def state(self) -> MissionState:
        done = failed = total = 0
        if self.log is not None:
            steps = self.log.steps()
            total = len(steps)
            done = sum(s.status == "done" for s in steps)
            failed = sum(s.status in ("failed", "skipped") for s in steps)
        return MissionState(
            stamp_ns=self.ctx.clock.now_ns(),
            mission=self.mission,
            phase=MissionPhase.PAUSED if self._paused.is_set() and self.active else self.phase,
            scans_done=done,
            scans_failed=failed,
            scans_total=total,
            current_scan=self.current,
            distance_m=self.distance,
            detail=self.detail,
        )

    @property
    def active(self) -> bool:
        return self._worker is not None and self._worker.is_alive()

    # --- commands ---
    def handle(self, cmd: MissionCommand) -> MissionState:
        match cmd:
            case MissionStart():
                if self.active:
                    raise RequestError(f"mission {self.mission} is already running")
                self._start(cmd)
            case MissionPause():
                self._paused.set()
                self.event("info", "paused by operator")
            case MissionResume():
                self._paused.clear()
                self.event("info", "resumed by operator")
            case MissionAbort():
                self._abort.set()
                self._paused.clear()
            case MissionStatusQuery():
                pass
        return self.state()

    def _load_plan(self, cmd: MissionStart) -> PlanResult:
        if cmd.plan_file:
            try:
                return msgspec.json.decode(Path(cmd.plan_file).read_bytes(), type=PlanResult)
            except OSError as exc:
                raise RequestError(
                    f"MissionStart.plan_file: {cmd.plan_file}: {exc.strerror}"
                ) from None
            except msgspec.DecodeError as exc:
                raise RequestError(f"MissionStart.plan_file: {cmd.plan_file}: {exc}") from None
        try:
            return self.ctx.bus.call(
                keys.PLANNER_PLAN, PlanRequest(name=cmd.field), timeout=self.cfg.plan_timeout_s
            )
        except RpcError as exc:
            raise RequestError(f"planner: {exc}") from None

    def _start(self, cmd: MissionStart) -> None:
        self.phase = MissionPhase.PLANNING
        plan = self._load_plan(cmd)
        try:
            segs = segments(plan)
        except ValueError as exc:
            self.phase = MissionPhase.IDLE
            raise RequestError(str(exc)) from None
        name = cmd.mission or f"{plan.field}-{time.strftime('%Y%m%d-%H%M%S')}"
        path = self.ctx.run_dir / name / "mission.db"
        if path.exists():
            raise RequestError(f"MissionStart.mission: {name} exists already in {path.parent}")
        log = MissionLog(path)
        steps = []
        for k, s in enumerate(x for x in segs if x.cand_id is not None):
            x, y, yaw = s.end
            steps.append((k + 1, int(s.cand_id or 0), x, y, yaw))
        log.create(
            name, plan.field, self.ctx.clock.now_ns(), msgspec.json.encode(plan).decode(), steps
        )
        (path.parent / "plan.json").write_bytes(msgspec.json.encode(plan))
        self.plan = plan
        self._launch(name, log, segs)

    def _launch(self, name: str, log: MissionLog, segs: list[Segment]) -> None:
        self.mission, self.log = name, log
        self._abort.clear()
        self._paused.clear()
        self._worker = threading.Thread(target=self._run_mission, args=(segs,), daemon=True)
        self._worker.start()
        self._publish_plan()

    def _publish_plan(self) -> None:
        """The mission's plan for the dashboard; on wall time, so a fast sim clock does
        not multiply the traffic."""
        if self.plan is not None:
            self.plan_pub.put(self.plan)
            self._plan_sent = time.monotonic()

    def resume_unfinished(self) -> None:
        """Continue the newest unfinished mission in the run folder, if any."""
        dbs = sorted(self.ctx.run_dir.glob("*/mission.db"), key=lambda p: p.stat().st_mtime)
        for path in reversed(dbs):
            log = MissionLog(path)
            m = log.mission()
            if m is not None and m["state"] in ("running", "paused"):
                plan = msgspec.json.decode(m["plan_json"], type=PlanResult)
                nxt = log.next_step()
                self.plan = plan
                self._launch(m["id"], log, segments(plan))
                self.event(
                    "info",
                    f"resuming mission {m['id']} at scan "
                    f"{nxt.scan_id if nxt else 'none (returning home)'}",
                )
                return
            log.close()

    # --- the survey ---
    def _wait(self, seconds: float) -> None:
        if not clk.sleep(self.ctx.clock, seconds, self._stop) or self._abort.is_set():
            raise Aborted
        while self._paused.is_set():
            if not clk.sleep(self.ctx.clock, 0.5, self._stop) or self._abort.is_set():
                raise Aborted

    def _drive(self, seg: Segment, route_id: str) -> bool:
        """Follow ``seg``; False if navigation stays blocked."""
        for attempt in range(self.cfg.blocked_retries + 1):
            self.ctx.bus.call(
                keys.NAV_CMD,
                FollowRoute(route_id=f"{route_id}.{attempt}", legs=seg.legs),
                timeout=10,
            )
            t0 = self.ctx.clock.now_ns()
            warned = False
            while True:
                self._wait(0.2)
                p = self.progress.get()
                if p is None or p.route_id != f"{route_id}.{attempt}":
                    continue
                if p.state == NavState.ARRIVED:
                    self.distance += sum(
                        math.hypot(lg.x1 - lg.x0, lg.y1 - lg.y0) for lg in seg.legs
                    )
                    return True
                if p.state == NavState.BLOCKED:
                    self.event("warning", f"{route_id}: navigation blocked (attempt {attempt + 1})")
                    break
                if p.state == NavState.NOT_LOCALIZED and not warned:
                    self.event("warning", f"{route_id}: localization lost, waiting")
                    warned = True
                elif p.state != NavState.NOT_LOCALIZED and warned:
                    self.event("info", f"{route_id}: localization back")
                    warned = False
                if (self.ctx.clock.now_ns() - t0) / 1e9 > self.cfg.route_timeout_s:
                    self.ctx.bus.call(keys.NAV_CMD, CancelRoute(route_id=route_id), timeout=10)
                    self.event("warning", f"{route_id}: no arrival in {self.cfg.route_timeout_s} s")
                    break
        return False

    def _settle(self) -> None:
        """Wait until the robot has been localized throughout the last ``settle_s`` and
        its mean speed and turn rate over them are below the still thresholds. The
        mean, not every sample: the estimate's turn rate carries the encoders'
        0.01 rad/s noise, so single samples cross any tight threshold."""
        window: list[tuple[int, PoseEstimate]] = []
        warned = False
        while True:
            self._wait(0.1)
            p = self.pose.get()
            if p is None:
                continue
            now = self.ctx.clock.now_ns()
            if not p.localized:
                if not warned:
                    self.event("warning", "localization lost before a scan: waiting")
                    warned = True
                window.clear()
                continue
            window.append((now, p))
            window = [(t, q) for t, q in window if (now - t) / 1e9 <= self.cfg.settle_s]
            if (now - window[0][0]) / 1e9 < 0.9 * self.cfg.settle_s:
                continue
            v = sum(q.v for _, q in window) / len(window)
            w = sum(q.w for _, q in window) / len(window)
            if abs(v) < self.cfg.still_speed and abs(w) < self.cfg.still_turn:
                return

    def _scan(self, idx: int, scan_id: int) -> bool:
        """One location's scan with retries; records it; False when it failed."""
        assert self.log is not None
        step = self.log.steps()[idx]
        resumed = step.status == "scanning"
        for attempt in range(step.attempts, self.cfg.scan_retries + 1):
            st = self.scanner.get()
            if resumed and st is not None and st.scan_id == scan_id:
                # the service died during this scan: take what the scanner has
                resumed = False
                if st.state in (ScannerState.DONE, ScannerState.SCANNING):
                    self.event("info", f"scan {scan_id}: found on the scanner after restart")
                    if self._await_scan(idx, scan_id):
                        return True
                    continue
            resumed = False
            self.log.update(
                idx, status="scanning", attempts=attempt + 1, started_ns=self.ctx.clock.now_ns()
            )
            prof = msgspec.structs.replace(self.cfg.profile, scan_id=scan_id)
            try:
                self.ctx.bus.call(
                    keys.SCANNER_CMD, StartScan(profile=prof, project=self.mission), timeout=10
                )
            except RpcError as exc:
                self.event("warning", f"scan {scan_id}: start failed: {exc}")
                self._wait(2.0)
                continue
            if self._await_scan(idx, scan_id):
                return True
        return False

    def _await_scan(self, idx: int, scan_id: int) -> bool:
        assert self.log is not None
        with self._lock:
            self._collect = []
        t0 = self.ctx.clock.now_ns()
        try:
            while True:
                self._wait(0.2)
                st = self.scanner.get()
                # a status from before this attempt (a retry follows an error for the
                # same scan id) says nothing about it
                if st is None or st.scan_id != scan_id or st.stamp_ns < t0:
                    continue
                if st.state == ScannerState.DONE:
                    with self._lock:
                        poses, self._collect = self._collect or [], None
                    self.log.update(
                        idx,
                        status="done",
                        file=st.file,
                        ended_ns=self.ctx.clock.now_ns(),
                        pitch=st.pitch,
                        roll=st.roll,
                        **pose_stats(poses),
                    )
                    return True
                if st.state == ScannerState.ERROR:
                    self.event("warning", f"scan {scan_id}: scanner error: {st.error}")
                    self._wait(1.0)
                    return False
                if (self.ctx.clock.now_ns() - t0) / 1e9 > self.cfg.scan_timeout_s:
                    self.event("warning", f"scan {scan_id}: no end in {self.cfg.scan_timeout_s} s")
                    self.ctx.bus.call(keys.SCANNER_CMD, StopScan(), timeout=10)
                    return False
        finally:
            with self._lock:
                self._collect = None

    def _run_mission(self, segs: list[Segment]) -> None:
        log = self.log
        assert log is not None
        try:
            by_cand = {s.cand_id: s for s in segs if s.cand_id is not None}
            for step in log.steps():
                if step.status in ("done", "failed", "skipped"):
                    continue
                self.current = step.scan_id
                tag = f"scan {step.scan_id} (location {step.cand_id})"
                if step.status in ("pending", "driving"):
                    self.phase, self.detail = MissionPhase.DRIVING, f"to {tag}"
                    log.update(step.idx, status="driving")
                    if not self._drive(by_cand[step.cand_id], f"{self.mission}.{step.scan_id}"):
                        log.update(step.idx, status="skipped", reason="navigation blocked")
                        self.event("error", f"{tag}: skipped, navigation blocked")
                        continue
                self.phase, self.detail = MissionPhase.SETTLING, tag
                self._settle()
                self.phase = MissionPhase.SCANNING
                if self._scan(step.idx, step.scan_id):
                    self.event("info", f"{tag}: done")
                else:
                    log.update(step.idx, status="failed", reason="scanner error")
                    self.event("error", f"{tag}: failed after {self.cfg.scan_retries + 1} attempts")
            home = [s for s in segs if s.cand_id is None]
            if self.cfg.return_to_origin and home:
                self.phase, self.detail, self.current = MissionPhase.RETURNING, "to Origin", 0
                self._drive(home[0], f"{self.mission}.home")
            log.set_state("done")
            self.event("info", f"mission {self.mission} done")
            self.detail = ""
            if self.cfg.register_on_done:
                self._register()  # its detail is set before the phase says done
            self.phase = MissionPhase.DONE
        except Aborted:
            if self._abort.is_set():
                log.set_state("aborted")
                self.phase = MissionPhase.ABORTED
                self.event("warning", f"mission {self.mission} aborted")
                self.ctx.bus.call(keys.NAV_CMD, CancelRoute(), timeout=5)
        except RpcError as exc:
            self.phase, self.detail = MissionPhase.FAILED, str(exc)
            self.event("error", f"mission {self.mission} stopped: {exc}")

    # --- registration at the end (see services/register/hook.py for why here) ---
    def _register(self) -> None:
        assert self.log is not None
        run_dir = self.log.path.parent

        def done(level: str, text: str) -> None:
            self.detail = text
            self.event(level, text)

        job = RegistrationJob(run_dir, done)
        try:
            job.start()
        except OSError as exc:
            self.event("error", f"registration not started: {exc}")
            return
        self._registration = job
        self.detail = REGISTERING
        self.event("info", f"{REGISTERING} the scans: log in {job.log_path}")

    def run(self, stop: threading.Event) -> None:
        self._stop = stop
        if self.cfg.resume:
            self.resume_unfinished()
        for _ in clk.ticks(self.ctx.clock, 1.0, stop):
            self.state_pub.put(self.state())
            if time.monotonic() - self._plan_sent >= PLAN_REPUBLISH_S:
                self._publish_plan()
        if self._registration is not None:
            self._registration.stop()
        if self.log is not None:
            self.log.close()


def build(ctx: Context, cfg: MissionConfig) -> MissionService:
    return MissionService(ctx, cfg)
