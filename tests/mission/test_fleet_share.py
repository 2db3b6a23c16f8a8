"""A plan split between robots is surveyed by each robot's mission in its share:
together the shares scan every location once, and a mission never surveys a split
plan whole (every location twice) or another robot's share."""

from __future__ import annotations

import logging
from pathlib import Path

import msgspec
import pytest

from common import keys
from common.clock import WallClock
from common.messages.mission import MissionAbort, MissionStart
from common.messages.plan import PlanResult
from common.rpc import until_served
from common.service import Context
from common.transport import RequestError
from phenorover.cli import main
from services.mission.config import MissionConfig
from services.mission.plan import segments
from services.mission.service import MissionService
from services.mission.sources import own_share
from tests.conftest import client


@pytest.fixture
def split(engr_split: PlanResult) -> PlanResult:
    return engr_split


def test_the_shares_scan_every_location_once(split: PlanResult) -> None:
    assert split.fleet is not None
    shares = [own_share(split, k) for k in (1, 2)]
    scanned = [s.cand_id for sh in shares for s in segments(sh) if s.cand_id is not None]
    assert sorted(scanned) == sorted(split.selected)  # each once, none left
    for k, sh in enumerate(shares, start=1):
        assert sh.share == k and sh.survey == split.fleet.parts[k - 1].survey
        assert sh.tour.order[0] == 0 and sh.tour.order[-1] == 0
        assert sh.tour.length == pytest.approx(sum(g.length for g in sh.legs))
        assert segments(sh)[-1].cand_id is None  # and home
    # a share travels as JSON (the plan file, the mission log) and stays itself
    again = msgspec.json.decode(msgspec.json.encode(shares[1]), type=PlanResult)
    assert own_share(again, 2) == again


def test_a_share_that_does_not_fit_the_plan_is_one_line(split: PlanResult) -> None:
    with pytest.raises(RequestError, match=r"split between 2 robots: set this robot's share"):
        own_share(split, 0)
    with pytest.raises(RequestError, match="no share 3"):
        own_share(split, 3)
    with pytest.raises(RequestError, match="robot 1's share, this robot's is 2"):
        own_share(own_share(split, 1), 2)
    whole = msgspec.structs.replace(split, fleet=None)
    assert own_share(whole, 0) is whole
    # one robot parked by its locations: its plan's one part is all of it
    assert split.fleet is not None
    alone = msgspec.structs.replace(
        split, fleet=msgspec.structs.replace(split.fleet, parts=split.fleet.parts[:1])
    )
    assert own_share(alone, 0) == alone.share_of(1)
    with pytest.raises(RequestError, match="share 1: the plan is not split"):
        own_share(whole, 1)


@pytest.mark.parametrize(
    ("flags", "says"),
    [
        (["--plan", "/nonexistent/plan.json"], "--plan /nonexistent/plan.json: No such file"),
        (["--robot", "a/b"], "--robot 'a/b': a namespace is"),
    ],
)
def test_mission_start_refuses_a_bad_plan_or_robot_in_one_line(
    flags: list[str], says: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    assert main(["mission", "start", *flags]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0], err


def test_mission_start_refuses_a_file_that_is_not_a_plan(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    bad = tmp_path / "plan.json"
    bad.write_text('{"field": 3}')
    assert main(["mission", "start", "--plan", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a plan" in err[0], err


def test_a_robots_mission_takes_its_share_of_the_plan_sent_over_zenoh(
    split: PlanResult, router_endpoint: str, tmp_path: Path
) -> None:
    """The base station sends the whole split plan to robot ``r2`` (its keys under
    its namespace); r2's mission logs the locations of share 2, in its order."""
    with (
        client(router_endpoint, "mission", namespace="r2") as bus,
        client(router_endpoint, "basestation") as base,
    ):
        ctx = Context("mission", "r2", bus, WallClock(), logging.getLogger("t"), tmp_path, "engr")
        service = MissionService(ctx, MissionConfig(register_on_done=False, share=2))
        cmd = keys.MISSION_CMD.within("r2")
        start = MissionStart(mission="r2-survey", plan=split)
        # until r2's queryable has reached the router
        state = until_served(lambda: base.call(cmd, start, timeout=1), 30.0)
        assert state.mission == "r2-survey"
        base.call(cmd, MissionAbort(), timeout=10)
        worker = service._worker
        assert worker is not None
        worker.join(30)
        log = service.log
        assert log is not None
        assert split.fleet is not None
        assert [s.cand_id for s in log.steps()] == split.fleet.parts[1].order[1:-1]
        assert state.scans_total == len(split.fleet.parts[1].order) - 2
        log.close()
