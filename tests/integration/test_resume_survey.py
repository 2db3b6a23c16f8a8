"""A deployment stopped mid-survey and started again: the mission service resumes
the survey before it serves a command (an operator's pause included), and ``phenorover
sim``'s survey follows it to its end, or with ``--new`` aborts it and starts its own.
One test: each deployment's start-up costs seconds of CI."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from common import keys
from common.messages.mission import (
    MissionPause,
    MissionPhase,
    MissionResume,
    MissionStart,
    MissionStatusQuery,
)
from common.transport import RpcError
from services.mission.cli import run_survey
from tests.conftest import Procs
from tests.integration.test_mission import TINY, Deployment, db


@pytest.fixture
def deploy(procs: Procs, tmp_path: Path) -> Iterator[Callable[[], Deployment]]:
    """Deployments one after the other in one folder (one run folder, one memory
    card); each client session is closed whatever the test's outcome."""
    made: list[Deployment] = []

    def start() -> Deployment:
        made.append(Deployment(procs, tmp_path))
        return made[-1]

    yield start
    for d in made:
        d.close()


def test_a_resumed_survey_is_followed_to_its_end_and_new_aborts_an_unfinished_one(
    deploy: Callable[[], Deployment], capsys: pytest.CaptureFixture[str]
) -> None:
    """Three deployments in one run folder: the first stopped paused on the way to scan
    2; the second resumes that survey and follows it to its end, then is stopped on the
    way to scan 1 of another; the third, under ``--new``, aborts that one."""
    d = deploy()
    s = d.start()
    d.wait(lambda x: x.phase == MissionPhase.DRIVING and x.current_scan == 2)
    d.bus.call(keys.MISSION_CMD, MissionPause(), timeout=60)
    d.wait(lambda x: x.phase == MissionPhase.PAUSED)
    d.stop()

    d = deploy()
    # resumed before the first command is served, still paused by its operator
    st = d.bus.call(keys.MISSION_CMD, MissionStatusQuery(), timeout=60)
    assert st.mission == s.mission and st.phase == MissionPhase.PAUSED, st
    with pytest.raises(RpcError, match=rf"mission {s.mission} is in progress .*mission abort"):
        d.bus.call(keys.MISSION_CMD, MissionStart(field=str(TINY)), timeout=60)
    d.bus.call(keys.MISSION_CMD, MissionResume(), timeout=60)
    final = run_survey(d.bus, str(TINY), timeout=300)
    assert final is not None and final.mission == s.mission, final
    assert final.phase == MissionPhase.DONE and final.scans_done == 3, final
    out = capsys.readouterr().out
    assert f"mission {s.mission} was interrupted and is resumed" in out
    assert [st.status for st in db(d, s.mission).steps()] == ["done"] * 3

    old = d.start()
    d.wait(lambda x: x.mission == old.mission and x.phase == MissionPhase.DRIVING)
    d.stop()

    d = deploy()
    # followed for a few seconds only: the new survey's end is every other test's
    final = run_survey(d.bus, str(TINY), timeout=5.0, new=True)
    assert final is not None and final.mission != old.mission and final.in_progress, final
    assert f"aborting mission {old.mission}" in capsys.readouterr().out
    assert db(d, old.mission).mission()["state"] == "aborted"  # type: ignore[index]
