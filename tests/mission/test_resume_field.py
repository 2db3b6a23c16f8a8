"""A mission left unfinished in the run folder is resumed only by a deployment of its
own field: the same plots, whatever the field file is called or where it lies."""

from __future__ import annotations

from pathlib import Path

import msgspec

from common.field import load_field
from services.mission.log import MissionLog
from services.mission.sources import surveys_field, unfinished
from services.planner.core import plan

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"


def test_a_plan_is_of_the_deployment_field_by_its_plots(tmp_path: Path) -> None:
    layout, field = load_field(TINY)
    tiny_plan = plan(layout, field=field)
    copy = tmp_path / "renamed.toml"
    copy.write_text(TINY.read_text())

    def surveys(deployment_field: str) -> bool:
        return surveys_field(deployment_field, tiny_plan)

    assert surveys(str(TINY)) and surveys(str(copy))
    assert not surveys("engr")
    assert not surveys(str(tmp_path / "missing.toml"))


def test_the_newest_unfinished_mission_of_the_field_is_found_and_nothing_else(
    tmp_path: Path,
) -> None:
    layout, field = load_field(TINY)
    text = msgspec.json.encode(plan(layout, field=field)).decode()
    runs = tmp_path / "runs"

    def mission(name: str, state: str, plan_json: str = text) -> None:
        log = MissionLog(runs / name / "mission.db")
        log.create(name, "tiny", 0, plan_json, [(1, 0, 0.0, 0.0, 0.0)])
        log.set_state(state)
        log.close()

    mission("a-done", "done")
    mission("b-paused", "paused")
    other = tmp_path / "other.toml"
    other.write_text(TINY.read_text().replace("plots_per_row = 3", "plots_per_row = 2"))
    mission(
        "c-other-field",
        "running",
        msgspec.json.encode(plan(load_field(other)[0], field=load_field(other)[1])).decode(),
    )
    (runs / "d-garbage").mkdir()
    (runs / "d-garbage" / "mission.db").write_bytes(b"\x00not sqlite" * 100)
    warnings: list[str] = []
    found = unfinished(runs, str(TINY), warnings.append)
    assert found is not None and found.mission == "b-paused" and found.paused
    found.log.close()
    assert len(warnings) == 2, warnings
    assert any("d-garbage" in w and "not a readable mission log" in w for w in warnings)
    assert any(w.startswith("mission c-other-field surveys field") for w in warnings)
    assert unfinished(tmp_path / "empty", str(TINY), warnings.append) is None
