"""The configuration record a mission keeps (services/mission/configs.py)."""

from __future__ import annotations

import tomllib
from pathlib import Path

from common.messages.system import ServiceConfig
from services.mission.configs import CONFIG_FILE, record


def _cfg(service: str, toml: str, machine: str = "robot") -> ServiceConfig:
    return ServiceConfig(service=service, machine=machine, toml=toml)


def test_the_record_reads_back_as_a_manifest_section_per_service(tmp_path: Path) -> None:
    said: list[tuple[str, str]] = []
    configs = [_cfg("nav", "rate_hz = 20.0\n[ekf]\ngate = true\n"), _cfg("planner", "", "base")]
    path = record(tmp_path, configs, lambda level, text: said.append((level, text)))
    assert path == tmp_path / CONFIG_FILE
    doc = tomllib.loads(path.read_text())
    assert doc["services"]["nav"] == {"rate_hz": 20.0, "ekf": {"gate": True}}
    assert doc["services"]["planner"] == {}
    assert doc["machines"] == {"nav": "robot", "planner": "base"}
    assert said == [("info", "configuration recorded in config.toml (nav, planner)")]


def test_a_resumed_mission_keeps_the_first_record_and_adds_what_changed(tmp_path: Path) -> None:
    said: list[tuple[str, str]] = []
    first = [_cfg("nav", "rate_hz = 20.0\n")]
    record(tmp_path, first, lambda level, text: said.append((level, text)))
    # the same services answering the same: nothing new
    assert record(tmp_path, first, lambda level, text: said.append((level, text))).name == (
        CONFIG_FILE
    )
    changed = record(tmp_path, [_cfg("nav", "rate_hz = 10.0\n")], lambda *a: said.append(a))
    assert changed.name == "config.resumed-1.toml"
    assert tomllib.loads((tmp_path / CONFIG_FILE).read_text())["services"]["nav"]["rate_hz"] == 20
    assert tomllib.loads(changed.read_text())["services"]["nav"]["rate_hz"] == 10
    assert len(said) == 2 and said[1][0] == "warning" and "config.resumed-1.toml" in said[1][1]


def test_a_section_that_is_not_toml_is_kept_as_text(tmp_path: Path) -> None:
    path = record(tmp_path, [_cfg("odd", "this is = = not toml")], lambda *a: None)
    assert tomllib.loads(path.read_text())["unreadable"]["odd"] == "this is = = not toml"
