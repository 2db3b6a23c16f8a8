from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from common.config import ConfigError, apply_overrides, load_manifest
from phenorover.preflight import validate
from tests.conftest import REPO

DEPLOY = REPO / "deploy"


@pytest.mark.parametrize("name", ["sim", "robot", "jetson", "basestation"])
def test_shipped_manifests_validate(name: str) -> None:
    m = validate(DEPLOY / f"{name}.toml")
    assert m.services


def test_split_manifests_cover_every_service_once() -> None:
    names = [
        s
        for n in ("robot", "jetson", "basestation")
        for s in load_manifest(DEPLOY / f"{n}.toml").services
    ]
    sim_only = {"sim"}
    assert set(names) == set(load_manifest(DEPLOY / "sim.toml").services) - sim_only
    assert len(names) == len(set(names))


def test_overrides_parse_toml_values_and_bare_words() -> None:
    out = apply_overrides({"a": {"b": 1}}, ["a.b=2.5", "name=sim", "flag=true", "xs=[1, 2]"])
    assert out == {"a": {"b": 2.5}, "name": "sim", "flag": True, "xs": [1, 2]}
    with pytest.raises(ConfigError, match="expected key=value"):
        apply_overrides({}, ["novalue"])


def test_bad_toml_names_the_file(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text("machine = \n")
    with pytest.raises(ConfigError, match=r"bad\.toml: not valid TOML"):
        load_manifest(p)
    with pytest.raises(ConfigError, match=r"nope\.toml: no such file"):
        load_manifest(tmp_path / "nope.toml")


def test_wrong_type_names_key_and_expectation(tmp_path: Path) -> None:
    p = tmp_path / "m.toml"
    p.write_text('machine = "x"\n[services.sim]\nreal_time_factor = "fast"\n')
    with pytest.raises(ConfigError) as e:
        validate(p)
    msg = str(e.value)
    assert "m.toml" in msg and "[services.sim]" in msg and "real_time_factor" in msg
    assert "Expected `float`" in msg


def test_service_dump_config_applies_overrides() -> None:
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "services.sim",
            "--manifest",
            str(DEPLOY / "sim.toml"),
            "--set",
            "real_time_factor=3",
            "--dump-config",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    assert "real_time_factor = 3.0" in r.stdout


def test_service_rejects_bad_override_with_one_line() -> None:
    r = subprocess.run(
        [sys.executable, "-m", "services.sim", "--set", "real_time_factor=-1", "--dump-config"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "real_time_factor" in r.stderr


@pytest.mark.parametrize("service", sorted(__import__("services").SERVICES))
def test_dumped_config_loads_back_unchanged(service: str, tmp_path: Path) -> None:
    from phenorover.launcher import config_type

    t = config_type(service, service)
    section = load_manifest(DEPLOY / "sim.toml").services.get(service, {})
    from common.config import decode_section, dump_toml

    cfg = decode_section(section, t, service)
    (tmp_path / "c.toml").write_text(dump_toml(cfg))
    from common.config import read_toml

    assert decode_section(read_toml(tmp_path / "c.toml"), t, "dumped") == cfg
