"""Several robots on one dashboard: each robot of ``[services.viz] robots`` (their
namespaces, :mod:`common.keys`) under ``fleet/<namespace>/``: its pose by its own
estimate (in simulation :mod:`phenorover.eval.truth_view` adds the truth beside it);
its share of the survey (the route its mission follows, in a colour of its own); its
mission's state, scans done and events. The field and the candidates come from the
first plan any robot publishes, each robot's locations from its own. Like the rest of
the dashboard it stores the newest message of each stream from the bus and draws on
the service's tick."""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import Any

import rerun as rr

from common import keys
from common.keys import Topic
from common.messages.mission import MissionEvent, MissionState
from common.messages.plan import PlanResult
from common.robot import Robot
from common.transport import Bus
from services.viz import scene
from services.viz.scene import Entry

# one colour a robot, in the order of ``robots``
COLOURS = [(255, 140, 0), (60, 130, 255), (200, 60, 200), (40, 200, 170), (230, 40, 40)]
STREAMS: dict[str, Topic[Any]] = {
    "pose": keys.NAV_POSE,
    "state": keys.MISSION_STATE,
    "plan": keys.MISSION_PLAN,
}


class FleetView:
    """``log(stamp_ns, entries)`` and ``static(entries)`` draw on the dashboard's
    streams."""

    def __init__(
        self,
        bus: Bus,
        robots: list[str],
        robot: Robot,
        log: Callable[[int, list[Entry]], None],
        static: Callable[[list[Entry]], None],
    ) -> None:
        self.robots, self.robot, self._log, self._static = robots, robot, log, static
        self._lock = threading.Lock()
        self._new: dict[tuple[str, str], Any] = {}
        self._events: list[tuple[str, MissionEvent]] = []
        self.plans: dict[str, PlanResult] = {}
        self.states: dict[str, MissionState] = {}
        self.field_drawn = False
        for ns in robots:
            for name, topic in STREAMS.items():
                bus.subscribe(topic.within(ns), functools.partial(self._put, ns, name))
            bus.subscribe(keys.MISSION_EVENT.within(ns), functools.partial(self._on_event, ns))

    def _put(self, ns: str, name: str, msg: Any) -> None:
        with self._lock:
            self._new[(ns, name)] = msg

    def _on_event(self, ns: str, e: MissionEvent) -> None:
        with self._lock:
            self._events.append((ns, e))

    def tick(self) -> None:
        with self._lock:
            new, self._new = self._new, {}
            events, self._events = self._events, []
        for (ns, name), msg in sorted(new.items(), key=lambda kv: kv[0][1] != "plan"):
            self._draw(ns, name, msg)
        for ns, e in events:
            self._log(e.stamp_ns, [self._event(ns, e)])

    def _draw(self, ns: str, name: str, m: Any) -> None:
        base = f"fleet/{ns}"
        if name == "plan":
            self._on_plan(ns, m)
        elif name == "pose":
            self._log(m.stamp_ns, [scene.pose(f"{base}/estimate", m.x, m.y, m.z, m.yaw)])
        elif name == "state":
            prev = self.states.get(ns)
            self.states[ns] = m
            entries = [Entry(f"{base}/scans_done", rr.Scalars(float(m.scans_done)))]
            if prev is None or (prev.mission, prev.phase, prev.detail) != (
                m.mission,
                m.phase,
                m.detail,
            ):
                text = f"{ns}: {m.mission}: {m.phase.value}" + (
                    f" ({m.detail})" if m.detail else ""
                )
                entries.append(
                    Entry(
                        f"{base}/log",
                        rr.TextLog(f"{text}, {m.scans_done}/{m.scans_total} scans", level="DEBUG"),
                    )
                )
            self._log(m.stamp_ns, entries)

    def _on_plan(self, ns: str, plan: PlanResult) -> None:
        if self.plans.get(ns) == plan:
            return
        self.plans[ns] = plan
        colour = COLOURS[self.robots.index(ns) % len(COLOURS)]
        legs = [[[g.x0, g.y0, scene.ROUTE_Z], [g.x1, g.y1, scene.ROUTE_Z]] for g in plan.legs]
        by_id = {c.id: c for c in plan.candidates}
        mine = [by_id[i] for i in plan.selected if i in by_id]
        locations = rr.Points3D(
            [[c.x, c.y, 0.0] for c in mine],
            colors=[colour],
            radii=[0.15],
            labels=[str(c.id) for c in mine],
        )
        entries = [
            Entry(f"fleet/{ns}/route", rr.LineStrips3D(legs, colors=[colour], radii=[0.05]), True),
            Entry(f"fleet/{ns}/locations", locations, True),
            scene.body(f"fleet/{ns}/estimate/body", self.robot, colour, label=ns),
        ]
        if not self.field_drawn:  # the plots and candidates: the same in every share
            shared = ("field/plots", "field/candidates")
            entries += [e for e in scene.plan_entries(plan) if e.path in shared]
            self.field_drawn = True
        self._static(entries)

    def _event(self, ns: str, e: MissionEvent) -> Entry:
        level = scene.LEVELS.get(e.level, "INFO")
        return Entry(f"fleet/{ns}/log", rr.TextLog(f"{ns}: {e.text}", level=level))
