from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import laspy
import pytest

from common.messages.plan import PlanResult
from phenorover.cli import main as phenorover_main
from services.traits.cli import main
from tests.traits.conftest import TINY, plan_for, write_run

OUTPUTS = (
    "traits.csv",
    "traits_long.csv",
    "traits.geojson",
    "fieldmap.png",
    "traits.toml",
    "traits.md",
    "entries.csv",
    "heritability.csv",
    "crop.json",
)


@pytest.fixture
def run_copy(sloped_run: Path, tmp_path: Path) -> Path:
    """A fresh copy of the sloped survey's folder (the tests write into it)."""
    run = tmp_path / sloped_run.name
    shutil.copytree(sloped_run, run)
    return run


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("phenorover traits: ")
    return err[0]


def test_writes_every_output(run_copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(run_copy), "--set", "min_seen=0.3", "--log-level", "warning"]) == 0
    for name in OUTPUTS:
        assert (run_copy / name).is_file(), name
    opts = tomllib.loads((run_copy / "traits.toml").read_text())
    assert opts["min_seen"] == 0.3 and opts["definition"]["cell"] == 0.05
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and "6 plots" in out[0] and "2024-06-03" in out[0]


def test_phenorover_traits_with_out_and_date(run_copy: Path, tmp_path: Path) -> None:
    out = tmp_path / "elsewhere"
    assert phenorover_main(["traits", str(run_copy), "--out", str(out), "--no-figures",
                            "--date", "2024-07-01"]) == 0  # fmt: skip
    assert "2024-07-01" in (out / "traits.csv").read_text()
    assert not (out / "fieldmap.png").exists() and not (run_copy / "traits.csv").exists()


def test_no_mission_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(tmp_path)]) == 2
    assert "mission.db" in _one_error_line(capsys)


def test_no_registered_cloud(run_copy: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (run_copy / "registered.laz").unlink()
    (run_copy / "traits.csv").write_text("earlier\n")
    assert main([str(run_copy)]) == 2
    line = _one_error_line(capsys)
    assert "registered.laz" in line and "phenorover register" in line
    assert (run_copy / "traits.csv").read_text() == "earlier\n"


@pytest.mark.parametrize("content", ["empty", "garbage"])
def test_unreadable_or_empty_cloud_leaves_earlier_outputs(
    run_copy: Path, content: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(run_copy), "--log-level", "warning"]) == 0
    before = {n: (run_copy / n).read_bytes() for n in OUTPUTS}
    capsys.readouterr()
    laz = run_copy / "registered.laz"
    if content == "empty":
        laspy.LasData(laspy.LasHeader(point_format=1, version="1.4")).write(str(laz))
    else:
        laz.write_bytes(b"LASF" + b"\x00" * 50)
    assert main([str(run_copy)]) == 2
    assert "registered.laz" in _one_error_line(capsys)
    assert {n: (run_copy / n).read_bytes() for n in OUTPUTS} == before


def test_plan_without_a_field(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from services.mission.log import MissionLog

    log = MissionLog(tmp_path / "mission.db")
    log.create("m", "tiny", 0, "", [])
    log.close()
    assert main([str(tmp_path)]) == 2
    assert "no plan" in _one_error_line(capsys)


def test_bad_date_and_bad_option(
    tiny_plan: PlanResult, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from common.field import load_field

    run = write_run(tmp_path / "run", plan_for(tiny_plan, load_field(TINY)[0]), None)
    assert main([str(run), "--date", "03/06/2024"]) == 2
    assert "YYYY-MM-DD" in _one_error_line(capsys)
    assert main([str(run), "--set", "min_seen=2"]) == 2
    assert "min_seen" in _one_error_line(capsys)
