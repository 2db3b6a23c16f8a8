"""The calibration table reads the benchmarks' figures by their names: every row's
figures are in the committed JSON, and a missing benchmark says so."""

from __future__ import annotations

import io
from pathlib import Path

from phenorover.eval import calibration_table as ct
from phenorover.eval.results import BENCH_DIR, Bench, Goal, load


def test_every_rows_figures_are_in_the_committed_benchmarks() -> None:
    names = {b: {f.name for f in load(BENCH_DIR / f"{b}.json").figures} for b in ct.BENCHES}
    for row in ct.ROWS:
        wanted = [row.baseline, row.ours, row.against_paper, row.ours_against_baseline]
        missing = [n for n in wanted if n is not None and n not in names[row.bench]]
        assert not missing, f"{row.bench} has no figure {missing}"


def test_a_row_sets_the_paper_the_baseline_and_ours_side_by_side(tmp_path: Path) -> None:
    label = "border: mean cross-track error, true pose"
    b = Bench("bench_profiles")
    b.figure(f"{label} [paper]", 2.8, "cm", paper=2.37, note="mean of 3 seeds")
    b.figure(f"{label} [ours]", 1.4, "cm", paper=2.37)
    b.figure(f"{label}{ct.AGAINST_PAPER}", 18.1, "%", goal=Goal("<=", 25.0, "x"))
    b.figure(f"{label}{ct.OURS_AGAINST}", 0.5, "x", goal=Goal("<=", 0.6, "x"))
    b.finish(tmp_path / "bench_profiles.json", out=io.StringIO())
    Bench("bench_survey").finish(tmp_path / "bench_survey.json", out=io.StringIO())
    lines = ct.section(tmp_path)
    row = next(line for line in lines if line.startswith(f"| {label} |"))
    assert row.split(" | ")[1:6] == [
        "2.37 cm",
        "2.8 cm (mean of 3 seeds)",
        "1.4 cm",
        "18.10% (<= 25%: met)",
        "0.5 x (<= 0.6 x: met)",
    ]
    # the survey's figures are not in this bench_survey.json: said, not dropped
    assert any("not measured" in line for line in lines if "true stop at each scan" in line)


def test_a_missing_benchmark_is_said(tmp_path: Path) -> None:
    lines = ct.section(tmp_path)
    assert lines[0] == ct.HEADING
    assert any(line.startswith("No table:") and "is missing" in line for line in lines)
