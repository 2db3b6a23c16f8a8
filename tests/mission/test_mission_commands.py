"""Operator commands that reach the mission service while it plans (the planner can
take minutes): a second MissionStart is refused, never run as a second survey beside
the first, and an abort sent meanwhile is obeyed before any route is sent.

The service runs in-process on a real bus, with a planner that holds its answer until
the test lets it go and a navigation that records what it is sent."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from common import keys
from common.clock import WallClock
from common.field import load_field
from common.messages.mission import MissionAbort, MissionPhase, MissionStart, MissionState
from common.messages.nav import FollowRoute, NavCommand, NavReply
from common.messages.plan import PlanRequest, PlanResult
from common.service import Context
from common.transport import Bus, RpcError
from services.mission.config import MissionConfig
from services.mission.service import MissionService
from services.planner.core import plan
from tests.conftest import client

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"


PROBE = "probe"  # a request HeldPlanner answers at once: the test's "are you there"


def reachable(bus: Bus, timeout: float = 30.0) -> bool:
    """Whether the planner answers through the router: its queryable reaches the
    router some time after it is declared, and a query before then finds nobody."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            bus.call(keys.PLANNER_PLAN, PlanRequest(name=PROBE), timeout=2)
            return True
        except RpcError:
            continue
    return False


class HeldPlanner:
    """Answers PLANNER_PLAN with the tiny field's plan once ``release`` is set."""

    def __init__(self, bus: Bus) -> None:
        layout, fld = load_field(TINY)
        self.result = plan(layout, field=fld)
        self.asked = threading.Event()
        self.release = threading.Event()
        bus.serve(keys.PLANNER_PLAN, self._plan)

    def _plan(self, req: PlanRequest) -> PlanResult:
        if req.name == PROBE:
            return self.result
        self.asked.set()
        assert self.release.wait(30), "the test never released the planner"
        return self.result


class RecordingNav:
    def __init__(self, bus: Bus) -> None:
        self.commands: list[NavCommand] = []
        bus.serve(keys.NAV_CMD, self._handle)

    def _handle(self, cmd: NavCommand) -> NavReply:
        self.commands.append(cmd)
        return NavReply(stamp_ns=0, accepted=True)


@pytest.fixture
def devices(router_endpoint: str) -> Iterator[Bus]:
    with client(router_endpoint, "devices") as bus:
        yield bus


def test_while_planning_a_second_start_is_refused_and_an_abort_is_obeyed(
    router_endpoint: str, client_bus: Bus, devices: Bus, tmp_path: Path
) -> None:
    planner, nav = HeldPlanner(devices), RecordingNav(devices)
    with client(router_endpoint, "mission") as bus:
        ctx = Context(
            "mission", "test", bus, WallClock(), logging.getLogger("t"), tmp_path, str(TINY)
        )
        service = MissionService(ctx, MissionConfig(register_on_done=False))
        first: list[MissionState | Exception] = []
        assert reachable(client_bus), "the planner never answered through the router"

        def start() -> None:
            try:
                first.append(client_bus.call(keys.MISSION_CMD, MissionStart(), timeout=30))
            except RpcError as exc:
                first.append(exc)

        starter = threading.Thread(target=start)
        starter.start()
        try:
            assert planner.asked.wait(10), "the mission never asked the planner"
            with pytest.raises(RpcError, match="being planned"):
                client_bus.call(keys.MISSION_CMD, MissionStart(), timeout=10)
            client_bus.call(keys.MISSION_CMD, MissionAbort(), timeout=10)
        finally:
            planner.release.set()
            starter.join(30)
        assert len(first) == 1 and isinstance(first[0], MissionState), first
        worker = service._worker
        assert worker is not None
        worker.join(10)
        assert service.phase == MissionPhase.ABORTED
        assert not [c for c in nav.commands if isinstance(c, FollowRoute)], nav.commands
        log = service.log
        assert log is not None
        mission = log.mission()
        assert mission is not None and mission["state"] == "aborted"
        log.close()
