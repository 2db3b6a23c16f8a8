"""The mission supervisor's Zenoh shell: runs a survey with nobody in the loop.

It takes commands, starts, pauses, resumes and aborts missions, walks each one's
locations (:mod:`.tour`), returns to the Origin and registers the scans. Every step
is committed to ``mission.db`` before the next begins; a restarted service resumes
at the first unfinished location and never scans a location twice.
"""

from __future__ import annotations

import threading
import time

from common import clock as clk
from common import keys
from common.messages.mission import (
    FINAL_PHASES,
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
from common.messages.plan import PlanResult
from common.service import Context
from common.transport import RequestError, RpcError
from services.mission.battery import BatteryWatch
from services.mission.config import MissionConfig
from services.mission.configs import save_configs
from services.mission.feeds import Aborted, Feeds
from services.mission.lanes import Lanes
from services.mission.log import MissionLog
from services.mission.plan import Segment, segments
from services.mission.registration import RegistrationJob, start_registration
from services.mission.sources import new_mission, requested_plan, unfinished
from services.mission.survey import Survey
from services.mission.tour import clock_started, return_home, walk

# wall seconds between copies of the plan on mission/plan, for subscribers joining late
PLAN_REPUBLISH_S = 5.0


class MissionService:
    def __init__(self, ctx: Context, cfg: MissionConfig) -> None:
        self.ctx, self.cfg = ctx, cfg
        bus = ctx.bus
        self.state_pub = bus.publisher(keys.MISSION_STATE)
        self.event_pub = bus.publisher(keys.MISSION_EVENT)
        self.plan_pub = bus.publisher(keys.MISSION_PLAN, in_step=False)  # dashboard's, wall time
        self.plan: PlanResult | None = None
        self._plan_sent = 0.0
        self.log: MissionLog | None = None
        self.mission = ""
        self.phase = MissionPhase.IDLE
        self.detail = ""
        self.current = 0
        self._paused = threading.Event()
        self._abort = threading.Event()
        self._wake = threading.Event()  # abort or stop: ends every wait at once
        self.survey: Survey | None = None
        self._worker: threading.Thread | None = None
        self._registrations: list[RegistrationJob] = []
        # one start at a time: a second MissionStart while one is being planned (up to
        # plan_timeout_s) is refused, never run as a second survey beside the first
        self._starting = threading.Lock()
        # the survey's feeds, subscribed once for every survey this service runs
        self.feeds = Feeds(bus)
        # the robots sharing the field ask this one's lane reservations at any time
        self.lanes = Lanes(ctx, cfg.lanes) if cfg.lanes.peers else None
        # an interrupted mission is taken up before the first command is served: a
        # MissionStart arriving while the service starts is refused (the mission in
        # progress named), never run beside the resumed one
        if cfg.resume:
            self.resume_unfinished()
        bus.serve(keys.MISSION_CMD, self.handle)

    def event(
        self, level: str, text: str, log: MissionLog | None = None, mission: str | None = None
    ) -> None:
        """Report on the current mission, or on ``mission`` (logged to ``log``)."""
        now = self.ctx.clock.now_ns()
        getattr(self.ctx.log, "warning" if level == "warning" else level)("%s", text)
        log = log or self.log
        if log is not None:
            log.event(now, level, text)
        name = self.mission if mission is None else mission
        self.event_pub.put(MissionEvent(stamp_ns=now, mission=name, level=level, text=text))

    def state(self) -> MissionState:
        done, failed, total = (0, 0, 0) if self.log is None else self.log.counts()
        return MissionState(
            stamp_ns=self.ctx.clock.now_ns(),
            mission=self.mission,
            phase=MissionPhase.PAUSED if self._paused.is_set() and self.active else self.phase,
            scans_done=done,
            scans_failed=failed,
            scans_total=total,
            current_scan=self.current,
            distance_m=self.survey.distance if self.survey else 0.0,
            detail=self.survey.detail if self.survey and self.active else self.detail,
            planned_m=self.plan.tour.length if self.plan else 0.0,
        )

    @property
    def active(self) -> bool:
        return self._worker is not None and self._worker.is_alive()

    # --- commands ---
    def handle(self, cmd: MissionCommand) -> MissionState:
        match cmd:
            case MissionStart():
                if not self._starting.acquire(blocking=False):
                    raise RequestError(
                        "another MissionStart is being planned; wait for its reply "
                        "(`phenorover mission status`)"
                    )
                try:
                    if self._worker is not None and self.phase in FINAL_PHASES:
                        self._worker.join(timeout=5.0)  # its final phase is its last act
                    if self.active:
                        raise RequestError(
                            f"mission {self.mission} is in progress (phase "
                            f"{self.state().phase}); wait for its end, or end it with "
                            "`phenorover mission abort`"
                        )
                    self._start(cmd)
                finally:
                    self._starting.release()
            case MissionPause():
                self._paused.set()
                self._persist_pause("paused")
                self.event("info", "paused by operator")
            case MissionResume():
                self._paused.clear()
                self._persist_pause("running")
                self.event("info", "resumed by operator")
            case MissionAbort():
                self._abort.set()
                self._wake.set()
                self._paused.clear()
            case MissionStatusQuery():
                pass
        return self.state()

    def _persist_pause(self, state: str) -> None:
        """An operator's pause outlives a restart of the service (a power cut): the
        resumed mission waits for ``mission resume`` instead of driving off."""
        if not self.active or self.log is None:
            return
        m = self.log.mission()
        if m is not None and m["state"] in ("running", "paused"):  # not a finished one
            self.log.set_state(state)

    def _start(self, cmd: MissionStart) -> None:
        before = self.phase
        # cleared before planning, not at the launch: an abort or a pause the operator
        # sends while the planner works is for this mission, and its worker obeys it
        # from its first step (the robot never drives off after an abort)
        self._abort.clear()
        self._wake.clear()
        self._paused.clear()
        self.phase = MissionPhase.PLANNING
        try:
            self._start_planned(cmd)
        except RequestError:
            self.phase = before  # a refused start leaves the state as it was
            raise

    def _start_planned(self, cmd: MissionStart) -> None:
        plan = requested_plan(self.ctx, cmd, self.cfg.plan_timeout_s, self.cfg.pace, self.cfg.share)
        name, log, segs = new_mission(self.ctx, plan, cmd.mission)
        self.plan = plan
        self._launch(name, log, segs)

    def _launch(self, name: str, log: MissionLog, segs: list[Segment]) -> None:
        """Run the survey of ``log`` on a worker; the operator's abort and pause are
        set (or cleared) by the caller, before planning."""
        self.mission, self.log = name, log
        save_configs(self.ctx.bus, self.ctx.run_dir / name, self.event)
        if self.lanes is not None and self.plan is not None:
            self.lanes.use(self.plan)
        if self._paused.is_set():
            log.set_state("paused")  # a pause sent while planning outlives a restart too
        self.survey = Survey(
            self.ctx,
            self.cfg,
            self.feeds,
            log,
            name,
            self.event,
            self._wake,
            self._abort,
            self._paused,
            self.lanes,
        )
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
        found = unfinished(
            self.ctx.run_dir, self.ctx.field, lambda text: self.event("warning", text)
        )
        if found is None:
            return
        nxt = found.log.next_step()
        self.plan = found.plan
        self.phase = MissionPhase.SETTLING  # until the worker's first step says
        self._abort.clear()
        self._wake.clear()
        if found.paused:
            self._paused.set()
        self._launch(found.mission, found.log, segments(found.plan))
        self.event(
            "info",
            f"resuming mission {found.mission} at scan "
            f"{nxt.scan_id if nxt else 'none (returning home)'}"
            + (" (paused by the operator: `phenorover mission resume`)" if found.paused else ""),
        )

    # --- the survey ---
    def _run_mission(self, segs: list[Segment]) -> None:
        log, sv = self.log, self.survey
        assert log is not None and sv is not None
        try:
            # a resumed survey waits for the clock: every deadline is taken from it
            if not clock_started(self.ctx.clock, self._wake, self.ctx.log):
                raise Aborted
            assert self.plan is not None
            battery = BatteryWatch(self, sv, self.cfg, self.plan, self.ctx.robot.battery)
            walk(self, log, sv, self.cfg, segs, self._wake, battery)
            if self.cfg.return_to_origin:
                return_home(self, sv, segs)
            log.set_state("done")
            self.event("info", f"mission {self.mission} done")
            self.detail = ""
            if self.cfg.register_on_done:
                self._register()  # its detail is set before the phase says done
            self.phase = MissionPhase.DONE
        # the final phase is set last: whoever sees it may start the next mission at once
        except Aborted:
            if self._abort.is_set():
                sv.cancel()
                log.set_state("aborted")
                self.event("warning", f"mission {self.mission} aborted")
                self.phase = MissionPhase.ABORTED
        except RpcError as exc:
            self.detail = str(exc)
            self.event("error", f"mission {self.mission} stopped: {exc}")
            self.phase = MissionPhase.FAILED

    # --- registration at the end (see services/mission/registration.py for why here) ---
    def _register(self) -> None:
        log, mission = self.log, self.mission
        assert log is not None

        def detail(text: str) -> None:
            # the next mission may have started meanwhile: the detail is this one's
            # only while it is current (its events go to its own log regardless)
            if self.mission == mission:
                self.detail = text

        job = start_registration(
            log.path.parent,
            self.ctx.manifest,
            self.cfg.traits_on_done,
            detail,
            lambda level, text: self.event(level, text, log, mission),
        )
        if job is not None:
            self._registrations.append(job)

    def run(self, stop: threading.Event) -> None:
        for _ in clk.ticks(self.ctx.clock, 1.0, stop):
            self.state_pub.put(self.state())
            if time.monotonic() - self._plan_sent >= PLAN_REPUBLISH_S:
                self._publish_plan()
        self._wake.set()
        if self._worker is not None:
            self._worker.join(timeout=2.0)
        for job in self._registrations:
            job.stop()
        if self.log is not None:
            self.log.close()


def build(ctx: Context, cfg: MissionConfig) -> MissionService:
    return MissionService(ctx, cfg)
