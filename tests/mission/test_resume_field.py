"""A mission left unfinished in the run folder is resumed only by a deployment of its
own field: the same plots, whatever the field file is called or where it lies."""

from __future__ import annotations

import types
from pathlib import Path

from common.field import load_field
from services.mission.service import MissionService
from services.planner.core import plan

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.toml"


def test_a_plan_is_of_the_deployment_field_by_its_plots(tmp_path: Path) -> None:
    layout, field = load_field(TINY)
    tiny_plan = plan(layout, field=field)
    copy = tmp_path / "renamed.toml"
    copy.write_text(TINY.read_text())

    def surveys(deployment_field: str) -> bool:
        fake = types.SimpleNamespace(ctx=types.SimpleNamespace(field=deployment_field))
        return MissionService._surveys_this_field(fake, tiny_plan)  # type: ignore[arg-type]

    assert surveys(str(TINY)) and surveys(str(copy))
    assert not surveys("engr")
    assert not surveys(str(tmp_path / "missing.toml"))
