"""What the launcher checks before it starts anything: a field without georeference
runs in simulation at the default origin and is refused on the robot, in one line,
before a router or a service is started; settings a service would refuse only once
started (against the robot, against the field) are refused there too."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

import phenorover.launcher
from common.config import ConfigError
from common.field_geojson import DEFAULT_ORIGIN
from phenorover.cli import main
from phenorover.findings import check
from phenorover.preflight import preflight
from tests.conftest import REPO, free_port

NO_ORIGIN = REPO / "tests" / "data" / "no_origin.toml"
ANTENNAS = '[{ id = 1, host = "127.0.0.1", tcp_port = 9001 }, { id = 2, host = "127.0.0.1" }]'


HARDWARE = f"""[services.gnss]
backend = "nmea-tcp"
antennas = {ANTENNAS}
[services.nav]
[services.mission]
"""
SIMULATED = """[services.sim]
[services.gnss]
backend = "sim"
[services.nav]
[services.planner]
[services.viz]
"""


def manifest(tmp: Path, machine: str, clock: str, field: Path | str, services: str) -> Path:
    """``tmp/<machine>.toml`` on loopback, its run folder in ``tmp``."""
    m = tmp / f"{machine}.toml"
    m.write_text(f"""machine = "{machine}"
clock = "{clock}"
field = "{field}"
run_dir = "{tmp / "runs"}"
[zenoh]
listen = ["tcp/127.0.0.1:{free_port()}"]
{services}""")
    return m


def hardware(tmp: Path, field: Path = NO_ORIGIN, extra: str = "") -> Path:
    """A robot's manifest (wall clock, hardware backends)."""
    return manifest(tmp, "robot", "wall", field, HARDWARE + extra)


def simulated(tmp: Path, extra: str = "") -> Path:
    """A simulated deployment's manifest."""
    return manifest(tmp, "sim", "sim", "engr", SIMULATED + extra)


@pytest.fixture
def started(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """What the launcher would have opened or started, were it to get that far."""
    seen: list[str] = []

    def spawn(_self: Any, child: Any) -> None:
        seen.append(child.name)

    def open_router(*_: Any) -> None:
        seen.append("router")
        raise AssertionError("the router was opened")

    monkeypatch.setattr(phenorover.launcher.Launcher, "_spawn", spawn)
    monkeypatch.setattr(phenorover.launcher.zenoh, "open", open_router)
    return seen


def test_a_simulated_deployment_places_the_field_given_at_the_default_origin(
    tmp_path: Path,
) -> None:
    manifest, notes = preflight(simulated(tmp_path), str(NO_ORIGIN))
    assert manifest.field == str(NO_ORIGIN)  # the field given replaces the manifest's
    lat, lon = DEFAULT_ORIGIN
    assert notes == [
        f"field 'h3' has no georeference: placed at the default origin {lat:.6f} N, "
        f"{-lon:.6f} W (simulation only; set origin_lat/origin_lon to survey it)"
    ]
    launcher = phenorover.launcher.Launcher(simulated(tmp_path), field=str(NO_ORIGIN))
    assert launcher.notes == notes
    assert all(launcher.extra_args[n][:2] == ["--field", str(NO_ORIGIN)] for n in launcher.children)
    # a field of its own origin needs no note
    assert preflight(simulated(tmp_path), "engr")[1] == []


def test_up_on_the_robot_refuses_it_in_one_line_and_starts_nothing(
    tmp_path: Path, started: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["up", str(hardware(tmp_path))]) == 2
    assert started == []
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert f"robot.toml: field: {NO_ORIGIN}: field 'h3' has no georeference" in err[0]
    assert "origin_lat, origin_lon are not set" in err[0]


def test_sim_with_the_field_on_a_real_deployment_refuses_it_before_anything_starts(
    tmp_path: Path, started: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    # the field given on the command line is checked, not only the manifest's
    manifest = hardware(tmp_path, field=REPO / "tests" / "data" / "tiny.toml")
    assert main(["sim", "--manifest", str(manifest), "--field", str(NO_ORIGIN)]) == 2
    assert started == []
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "origin_lat, origin_lon are not set" in err[0], err


@pytest.mark.parametrize("check_only", [False, True])
def test_the_cli_refuses_it_with_exit_2_and_one_line(tmp_path: Path, check_only: bool) -> None:
    cmd = ["up", "--check"] if check_only else ["up"]
    r = subprocess.run(
        [sys.executable, "-m", "phenorover", *cmd, str(hardware(tmp_path))],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr  # no router's or service's line: nothing started
    assert str(NO_ORIGIN) in lines[0] and "origin_lat, origin_lon are not set" in lines[0]
    if not check_only:
        assert r.stdout == ""


def test_a_follower_faster_than_the_robot_is_refused_before_nav_starts(tmp_path: Path) -> None:
    extra = "[services.nav.follower]\nmax_speed = 50.0\n"
    manifest = simulated(tmp_path, extra)
    with pytest.raises(ConfigError, match=r"sim\.toml: \[services\.nav\.follower\] max_speed = 50"):
        preflight(manifest)
    _, problems = check(manifest)
    assert [p for p in problems if "max_speed = 50" in p] == problems and len(problems) == 1


def test_a_field_beyond_the_planners_budget_is_refused_before_the_planner_starts(
    tmp_path: Path,
) -> None:
    extra = "[services.planner.budget]\nmax_cell_candidates = 1000\n"
    manifest = simulated(tmp_path, extra)
    with pytest.raises(ConfigError, match=r"sim\.toml: field engr: field 'engr': .*budget"):
        preflight(manifest)
    _, problems = check(manifest)
    assert len(problems) == 1 and "planner: field engr" in problems[0], problems
