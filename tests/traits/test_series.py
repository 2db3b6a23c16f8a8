"""A season: several surveys of one field as per-plot series, checked against each
other on stable ground first; runs of two fields, undated runs and two runs of one
date are refused in one line."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import msgspec
import numpy as np
import pytest

from common.field import build_field, load_field
from common.messages.plan import PlanResult
from services.traits.cli import main
from services.traits.config import TraitsConfig
from services.traits.series import season
from tests.traits.conftest import (
    CANOPIES,
    CREATED_NS,
    SLOPE,
    TINY,
    book_layout,
    plan_for,
    synthetic_cloud,
    write_run,
)

DAY_NS = 86_400 * 10**9


def _grown(by: float) -> list:
    return [c if c.height is None else dataclasses.replace(c, height=c.height + by)
            for c in CANOPIES]  # fmt: skip


@pytest.fixture(scope="module")
def runs(tiny_plan: PlanResult, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Three surveys 10 days apart, the canopies 10 cm taller each time, the last one
    with the whole cloud 3 cm higher (a registration's vertical offset)."""
    layout = book_layout(load_field(TINY)[0])
    pr = plan_for(tiny_plan, layout)
    field = build_field(layout)
    root = tmp_path_factory.mktemp("season")
    out = []
    for k in range(3):
        xyz = synthetic_cloud(field, _grown(0.1 * k), slope=SLOPE, seed=k)
        if k == 2:
            xyz[:, 2] += 0.03
        out.append(write_run(root / f"tiny-{k}", pr, xyz, CREATED_NS + 10 * k * DAY_NS))
    return out


def test_growth_is_measured_and_a_vertical_offset_corrected(runs: list[Path]) -> None:
    s = season(list(reversed(runs)), TraitsConfig())  # any order: sorted by date
    assert [r.run_dir for r in s.runs] == runs
    assert list(s.days) == [0.0, 10.0, 20.0]  # no planting date: days since the first
    assert s.offsets[0] is None and not s.corrected[1]
    off = s.offsets[2]
    assert off is not None and off.median_m == pytest.approx(0.03, abs=0.003)
    assert s.corrected == [False, False, True]
    grew = s.growth[np.isfinite(s.growth)]
    assert grew.size and np.allclose(grew, 0.1, atol=0.015)
    assert len(s.fits) == 6


def test_the_command_writes_the_season(runs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "season"
    assert main([*map(str, runs), "--out", str(out), "--log-level", "warning"]) == 0
    for name in ("season.csv", "season.md", "growth_fits.csv", "growth.png"):
        assert (out / name).is_file(), name
    for run in runs:
        assert (out / run.name / "traits.csv").is_file()
    rows = list(csv.DictReader((out / "season.csv").open()))
    assert len(rows) == 18 and rows[0]["plot"] == "101"
    assert "corrected" in (out / "season.md").read_text()


def _ours(run: Path) -> list[str]:
    """The run folder's files, without SQLite's -wal/-shm, which any reader of the
    (WAL) mission log brings back while it reads."""
    return sorted(p.name for p in run.iterdir() if not p.name.endswith(("-wal", "-shm")))


def test_runs_of_two_fields_are_refused(
    runs: list[Path], tiny_plan: PlanResult, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    layout = book_layout(load_field(TINY)[0])
    moved = msgspec.structs.replace(layout, name="elsewhere", plot_length=2.0)
    xyz = synthetic_cloud(build_field(moved), CANOPIES, slope=SLOPE)
    run = write_run(tmp_path / "else", plan_for(tiny_plan, moved), xyz, CREATED_NS + DAY_NS)
    before = _ours(runs[0])
    assert main([str(runs[0]), str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different fields" in err[0]
    assert _ours(runs[0]) == before


def test_two_runs_of_one_date_are_refused(
    runs: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([str(runs[0]), str(runs[0])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "both surveys of" in err[0]


def test_a_season_on_a_dask_cluster_is_the_season_computed_here(
    runs: list[Path], tmp_path: Path
) -> None:
    pytest.importorskip("distributed")
    here, there = tmp_path / "here", tmp_path / "there"
    args = [*map(str, runs), "--no-figures", "--log-level", "warning"]
    assert main([*args, "--out", str(here)]) == 0
    assert main([*args, "--out", str(there), "--workers", "2"]) == 0
    files = sorted(p.relative_to(here) for p in here.rglob("*") if p.is_file())
    assert files and files == sorted(p.relative_to(there) for p in there.rglob("*") if p.is_file())
    for f in files:
        assert (here / f).read_bytes() == (there / f).read_bytes(), f
