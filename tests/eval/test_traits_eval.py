"""``phenorover eval traits``: a survey's traits.csv scored against the plants' truth
the simulator wrote, plot by plot; a truth of another date or field is one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from phenorover.cli import main

HEAD = (
    "plot,row,column,rep,entry,height (m),height_p50 (m),height_max (m),cover (1),"
    "volume_voxel (m3),volume_hull (m3),points (1),seen (1),quality,date\n"
)


def _run(tmp_path: Path, date: str = "2026-07-10") -> Path:
    run = tmp_path / "runs" / "trial-1"
    run.mkdir(parents=True)
    (run / "traits.csv").write_text(
        HEAD
        + f"101,1,1,1,G01,1.20,1.0,1.25,0.8,0.5,1.9,1000,0.9,ok,{date}\n"
        + f"102,1,2,1,G02,1.00,0.9,1.05,0.7,0.4,1.5,1000,0.9,ok,{date}\n"
        + f"103,1,3,1,G03,0.50,0.4,0.55,0.3,0.1,0.5,100,0.2,occluded,{date}\n"
    )
    plots = [
        {"plot_id": p, "height": h, "height_max": h + 0.05, "cover": 0.8, "volume_voxel": 1.0,
         "volume_hull": 2.0}
        for p, h in (("101", 1.21), ("102", 0.97), ("103", 1.1))
    ]  # fmt: skip
    (tmp_path / "runs" / "sim").mkdir()
    (tmp_path / "runs" / "sim" / "plants.truth.json").write_text(
        json.dumps(
            {"evaluation_only": True, "field": "trial", "date": "2026-07-10", "plots": plots}
        )
    )
    return run


def test_the_plots_flagged_ok_are_scored(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = _run(tmp_path)
    assert main(["eval", "traits", str(run)]) == 0
    res = json.loads((run / "eval_traits.json").read_text())
    h = res["height"]
    assert h["n"] == 2 and h["flagged"] == 1
    assert h["bias"] == pytest.approx((-0.01 + 0.03) / 2)
    assert "height: RMSE 2.24 cm" in capsys.readouterr().out


def test_a_truth_of_another_date_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = _run(tmp_path, date="2026-07-31")
    assert main(["eval", "traits", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not the same survey" in err[0]
    assert not (run / "eval_traits.json").exists()


def test_traits_of_another_definition_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = _run(tmp_path)
    truth = tmp_path / "runs" / "sim" / "plants.truth.json"
    t = json.loads(truth.read_text())
    t["definition"] = {"cell": 0.05, "voxel": 0.1, "min_height": 0.05, "height_percentile": 99.0}
    truth.write_text(json.dumps(t))
    (run / "traits.toml").write_text(
        "[definition]\ncell = 0.05\nvoxel = 0.1\nmin_height = 0.05\nheight_percentile = 95.0\n"
    )
    assert main(["eval", "traits", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not the same measure" in err[0]
