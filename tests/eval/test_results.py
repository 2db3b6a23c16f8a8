"""The benchmark result schema, its writer and docs/results.md's renderer, on small
synthetic results (no benchmark is run)."""

from __future__ import annotations

import io
import json
import math
import subprocess
from pathlib import Path
from typing import Any

import pytest

from phenorover.eval import registration, render_results
from phenorover.eval.bench_schema import SCHEMA, Goal, ResultError, Target, load, verdict
from phenorover.eval.results import Bench, format_value, git_commit, seed_runs, spread
from tests.bench import bench_nav

CLOSE = "an IMU's roll and pitch in the filter"


def quiet() -> io.StringIO:
    return io.StringIO()


def test_verdicts() -> None:
    assert verdict(1.9, Target("<=", 2.0)) == "met"
    assert verdict(2.0, Target("<=", 2.0)) == "met"
    assert verdict(2.1, Target("<=", 2.0)) == "missed"
    assert verdict(91.0, Target(">=", 90.0)) == "met"
    assert verdict(86.0, Target(">=", 90.0)) == "missed"
    assert verdict(None, Target("<=", 2.0)) == "missed"  # not measured is not met
    assert verdict(5.0, None) == "no target"
    assert verdict(None, None) == "no target"


def test_a_goal_says_what_would_close_it() -> None:
    with pytest.raises(ValueError, match="close"):
        Goal("<=", 1.0, "  ")
    with pytest.raises(ValueError, match="op"):
        Goal("<", 1.0, "x")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="finite"):
        Goal("<=", math.nan, "x")


def test_a_missed_target_carries_its_figure_and_what_would_close_it() -> None:
    b = Bench("bench_x", {"RTK fix": "7 mm + 1 ppm"})
    met = b.figure("a", 0.3, "cm", goal=Goal("<=", 0.5, CLOSE))
    missed = b.figure("true stop", 2.95, "cm", goal=Goal("<=", 0.5, CLOSE), headline=True)
    free = b.figure("c", 7.0, "m")
    assert (met.verdict, met.what_would_close_it) == ("met", "")
    assert (missed.verdict, missed.value, missed.what_would_close_it) == ("missed", 2.95, CLOSE)
    assert missed.target == Target("<=", 0.5) and missed.headline
    assert (free.verdict, free.target) == ("no target", None)
    for f in (met, missed, free):
        assert f.error_models == {"RTK fix": "7 mm + 1 ppm"}
        assert f.date and f.commit and f.machine


def test_a_figure_not_measured_has_no_value_and_says_why() -> None:
    b = Bench("bench_x")
    with pytest.raises(ValueError, match="no reason"):
        b.figure("a", None, "cm")
    f = b.figure("a", None, "cm", goal=Goal("<=", 1.0, CLOSE), missing="nav-test exited 1")
    assert (f.value, f.verdict) == (None, "missed")
    assert f.what_would_close_it == "not measured: nav-test exited 1"
    g = b.figure("b", math.inf, "s")
    assert g.value is None and "inf" in g.what_would_close_it


def test_written_results_load_back_and_a_failure_exits_non_zero(tmp_path: Path) -> None:
    ok = Bench("bench_ok")
    ok.figure("x", 1.0, "s", goal=Goal("<=", 2.0, "faster"))
    assert ok.finish(tmp_path / "ok.json", {"raw": [1, 2]}, out=quiet()) == 0
    res = load(tmp_path / "ok.json")
    assert (res.schema, res.benchmark, res.exit_code, res.failures) == (
        SCHEMA,
        "bench_ok",
        0,
        [],
    )
    assert res.figures[0].verdict == "met" and res.details == {"raw": [1, 2]}

    bad = Bench("bench_bad")
    bad.fail("stationary", "nav-test stationary exited 1: never localized")
    out = quiet()
    assert bad.finish(tmp_path / "bad.json", out=out) == 1
    assert "FAILED stationary: nav-test stationary exited 1" in out.getvalue()
    assert load(tmp_path / "bad.json").exit_code == 1


def test_the_printed_summary_gives_the_error_models_beside_the_figures() -> None:
    b = Bench("bench_x", {"wheel slip": "1 % forward"})
    b.figure("true stop", 2.95, "cm", goal=Goal("<=", 0.5, CLOSE), headline=True)
    b.figure("free", 3.0, "m")
    out = quiet()
    b.finish(None, out=out)
    text = out.getvalue()
    assert "* true stop: 2.95 cm (target <= 0.5 cm: missed)" in text
    assert "  free: 3 m (no target)" in text
    assert f"what would close it: {CLOSE}" in text
    assert "wheel slip: 1 % forward" in text


def test_a_benchmark_run_in_part_keeps_the_rest_of_an_earlier_file(tmp_path: Path) -> None:
    old = Bench("bench_p")
    old.figure("border: xte", 1.4, "cm")
    old.figure("stationary: stop", 1.2, "cm")
    old.finish(tmp_path / "p.json", {"runs": {"ours": {"border": [1]}}}, out=quiet())
    kept = load(tmp_path / "p.json").figures[0]

    new = Bench("bench_p")
    earlier = new.carry(tmp_path / "p.json", ["border:"])
    new.figure("stationary: stop", 0.9, "cm")
    assert earlier is not None and earlier.details["runs"] == {"ours": {"border": [1]}}
    assert [(f.name, f.value) for f in new.figures] == [
        ("border: xte", 1.4),
        ("stationary: stop", 0.9),
    ]
    assert (new.figures[0].date, new.figures[0].commit) == (kept.date, kept.commit)
    assert Bench("bench_p").carry(tmp_path / "none.json", ["border:"]) is None


def test_the_seeds_spread_is_said_beside_a_mean() -> None:
    assert spread([1.0, 2.0, 3.0]) == "mean of 3 seeds, SD 1: 1, 2, 3"
    assert spread([0.7]) == spread([]) == ""


def test_several_runs_of_a_seed_are_averaged_and_their_spread_said() -> None:
    means, note = seed_runs([[1.0, 3.0], [2.0, 2.0], [4.0, 6.0]])
    assert means == [2.0, 2.0, 5.0]
    # pooled SD of the runs: variances 2, 0, 2 -> sqrt(4/3)
    assert note == (
        "mean of 3 seeds x 2 runs, SD 1.73 over the seeds' means: 2, 2, 5; "
        "SD 1.15 between runs of one seed"
    )
    # one run per seed reads as before
    assert seed_runs([[1.0], [2.0], [3.0]]) == ([1.0, 2.0, 3.0], spread([1.0, 2.0, 3.0]))
    assert seed_runs([[], [2.5, 3.5]])[0] == [3.0]


def test_loading_a_missing_or_older_file_says_so(tmp_path: Path) -> None:
    with pytest.raises(ResultError, match="is missing"):
        load(tmp_path / "none.json")
    (tmp_path / "old.json").write_text(json.dumps({"border": {"xte_mean_cm": 1.4}}))
    with pytest.raises(ResultError, match="older format"):
        load(tmp_path / "old.json")
    (tmp_path / "junk.json").write_text("{")
    with pytest.raises(ResultError, match="not JSON"):
        load(tmp_path / "junk.json")


def test_values_format_for_tables() -> None:
    assert format_value(None, "cm") == "not measured"
    assert format_value(11.0) == "11"
    assert format_value(2.9512, "cm") == "2.95 cm"
    assert format_value(97.31, "%") == "97.31%"
    assert format_value(0.0153, "s") == "0.0153 s"


def test_error_models_are_numbered_in_runs() -> None:
    assert render_results._ranges([1, 2, 3, 5, 7, 8]) == "[1-3, 5, 7-8]"
    assert render_results._ranges([]) == ""


def synthetic(bench_dir: Path) -> None:
    nav = Bench("bench_nav", {"terrain": "1 % slope"})
    nav.figure("stationary: true stop", 2.95, "cm", goal=Goal("<=", 0.5, CLOSE), headline=True)
    nav.figure("stationary: estimate against the plan (the paper's metric)", 0.33, "cm")
    nav.figure("border: mean cross-track error", 1.41, "cm", goal=Goal("<=", 2.0, "x"), paper=2.37)
    nav.fail("serpentine", "nav-test serpentine exited 1: route blocked")
    nav.figure("serpentine: heading error SD", None, "deg", missing="serpentine failed")
    nav.finish(bench_dir / "bench_nav.json", out=quiet())
    (bench_dir / "bench_devices.json").write_text('{"compass": {"sd_deg": 0.62}}')


def test_the_page_has_a_table_per_benchmark_and_says_what_is_missing(tmp_path: Path) -> None:
    bench_dir, docs = tmp_path / "runs" / "bench", tmp_path / "docs"
    bench_dir.mkdir(parents=True)
    docs.mkdir()
    (docs / "faults.md").write_text("# Faults\n")
    (bench_dir / "faults.json").write_text("[]")
    synthetic(bench_dir)
    page = render_results.render(bench_dir, docs)
    nav = page.split("## Navigation")[1].split("\n## ")[0]
    assert "| figure | value | target | verdict |" in nav
    assert "| stationary: true stop | **2.95 cm** | <= 0.5 cm | **missed** |" in nav
    assert "| 1.41 cm | <= 2 cm | met | 2.37 cm |" in nav
    assert (
        "- stationary: true stop: measured 2.95 cm against a target of <= 0.5 cm; "
        f"what would close it: {CLOSE}"
    ) in nav
    assert "**Failed**: serpentine: nav-test serpentine exited 1: route blocked" in nav
    assert "| [1] |" in nav and "- [1] terrain: 1 % slope" in nav
    assert "exit status 1" in nav
    assert "- serpentine: heading error SD: not measured: serpentine failed" in nav
    # no JSON, or an older one: said so, and no figures
    reg = page.split("## Registration")[1].split("\n## ")[0]
    assert "No results:" in reg and "bench_registration.json is missing" in reg
    assert "| figure |" not in reg
    dev = page.split("## Devices")[1].split("\n## ")[0]
    assert "No results:" in dev and "older format" in dev and "0.62" not in dev
    # the fault campaign and the soak are linked, not copied
    assert "[faults.md](faults.md), written by `make faults`" in page
    assert "[soak.md](soak.md) (not generated yet)" in page and "soak.json is missing" in page


def test_make_results_writes_the_page_and_keeps_a_benchmark_not_rerun(tmp_path: Path) -> None:
    bench_dir = tmp_path / "bench"
    bench_dir.mkdir()
    synthetic(bench_dir)
    out = tmp_path / "docs" / "results.md"
    assert render_results.main(["--bench-dir", str(bench_dir), "--out", str(out)]) == 0
    first = out.read_text()
    assert first.startswith("# Benchmark results")
    nav = first.split("## Navigation")[1].split("\n## ")[0]
    # bench_nav is not run where the page is rendered again: its table stays, marked
    (bench_dir / "bench_nav.json").unlink()
    for _ in range(2):  # and stays through a second rendering, marked once
        assert render_results.main(["--bench-dir", str(bench_dir), "--out", str(out)]) == 0
    again = out.read_text().split("## Navigation")[1].split("\n## ")[0]
    assert again.count("Carried from the previous page") == 1
    assert "bench_nav.json is missing" in again
    assert "| stationary: true stop | **2.95 cm** | <= 0.5 cm | **missed** |" in again
    assert nav.strip().splitlines()[1:] == again.strip().splitlines()[3:]
    # a benchmark that never had figures still says it has none
    reg = out.read_text().split("## Registration")[1].split("\n## ")[0]
    assert "No results:" in reg and "Carried" not in reg


def stationary_stats(true_cm: float, est_cm: float) -> dict[str, Any]:
    return {
        "experiment": "stationary",
        "hold_s": 420.0,
        "true_stop_to_planned_cm": true_cm,
        "true_heading_to_planned_deg": 0.29,
        "paper_estimate_to_planned_cm": est_cm,
        "paper_heading_residual_deg": 0.06,
        "estimate": {"residual_x_sd_cm": 0.04, "residual_y_sd_cm": 0.08},
        "estimate_error_cm": {"x": -2.0, "y": -2.1, "z": 0.2},
        "estimate_heading_error_deg": -0.14,
    }


def test_the_stationary_headline_is_the_true_stop() -> None:
    b = Bench("bench_nav")
    bench_nav.record(b, "stationary", stationary_stats(2.95, 0.33), "")
    by = {f.name: f for f in b.figures}
    head = [f for f in b.figures if f.headline]
    # a scan location is reached within the mission's 5 cm arrival tolerance
    stop = by["stationary: true stop against the planned point, mean distance over the hold"]
    assert stop in head and (stop.value, stop.verdict) == (2.95, "met")
    assert stop.target is not None and stop.target.value == 5.0
    paper = by["stationary: estimate against the planned point, mean distance (the paper's metric)"]
    assert paper not in head and (paper.value, paper.verdict) == (0.33, "no target")
    assert "tolerances" in paper.note and "where the robot stands" in paper.note
    # a scan location plans no heading: the true heading is shown, unscored; the
    # estimate's heading against the truth is what a scan inherits
    kept = by["stationary: true heading against the leg's heading, mean magnitude"]
    assert kept not in head and kept.verdict == "no target"
    heading = by["stationary: estimate's heading against the true heading, mean over the hold"]
    assert heading in head and (heading.value, heading.verdict) == (0.14, "missed")
    lean = by["stationary: estimate against the truth, horizontal (mean over the hold)"]
    assert lean.value == pytest.approx(math.hypot(2.0, 2.1))


def test_a_stop_beyond_the_arrival_tolerance_names_the_follower_s_tolerances() -> None:
    b = Bench("bench_nav")
    bench_nav.record(b, "stationary", stationary_stats(6.2, 5.9), "")
    stop = next(f for f in b.figures if f.name.startswith("stationary: true stop"))
    assert stop.verdict == "missed" and "fine_tolerance_m" in stop.what_would_close_it


def test_a_failed_experiment_is_not_measured_and_fails_the_benchmark() -> None:
    b = Bench("bench_nav")
    why = "nav-test border exited 1: never localized"
    b.fail("border", why)
    bench_nav.record(b, "border", None, why)
    assert b.figures and all(f.value is None for f in b.figures)
    assert all(f.what_would_close_it == f"not measured: {why}" for f in b.figures)
    assert b.finish(None, out=quiet()) == 1


def test_the_driven_distance_is_measured_beside_the_planned_length() -> None:
    b = Bench("bench_nav")
    stats = {"result": "arrived", "xte_mean_cm": 1.4, "share_below_5cm": 0.98}
    bench_nav.record(b, "border", {**stats, "planned_route_m": 90.0, "driven_true_m": 91.3}, "")
    by = {f.name: f for f in b.figures}
    assert by["border: distance driven, the true path"].value == 91.3
    planned = by["border: route length, planned"]
    assert planned.value == 90.0 and "planned" in planned.note
    assert by["border: share of the path below 5 cm"].value == pytest.approx(98.0)


def test_the_registration_headline_is_the_point_error_against_truth() -> None:
    def vs_reference(mean: float) -> dict[str, Any]:
        return {
            "points_vs_reference": {"count": 9, "mean": mean, "max": 0.1, "per_scan_mean": []},
            "targets_vs_reference": {"count": 3, "mean": 0.004},
            "overlap": {"radius": 0.3, "count": 99, "mean": 0.021, "max": 0.03, "pairs": []},
        }

    def vs_truth(mean: float) -> dict[str, Any]:
        return {
            "points": {"count": 9, "mean": mean, "max": 0.15, "per_scan_mean": []},
            "targets": {"count": 3, "mean": 0.009},
        }

    report = {"c2c": vs_reference(0.0120), "navigation": vs_reference(0.02), "time_s": 9.0}
    truth = {
        "scans": 11,
        "methods": {"c2c": vs_truth(0.0189), "navigation": vs_truth(0.0246)},
    }
    b = Bench("bench_registration")
    registration.record(b, report, truth)
    head = [f for f in b.figures if f.headline]
    assert head[0].name.endswith("mean point error against the truth")
    assert head[0].value == pytest.approx(1.89) and head[0].verdict == "missed"
    assert head[0].what_would_close_it
    ref = next(f for f in b.figures if "C2C: mean point error against the target-based" in f.name)
    assert ref.value == pytest.approx(1.20) and ref.verdict == "no target" and ref.paper is None
    # the paper's scan point statistics are set beside ours computed as SCENE does
    scene = next(f for f in b.figures if f.name.startswith("nav + C2C: mean point error between"))
    assert scene.value == pytest.approx(2.1) and scene.paper == 2.07
    assert not any("clouds alone" in f.name for f in b.figures)  # not in this registration
    tb = next(f for f in b.figures if f.name.startswith("target-based, all scans"))
    assert tb.value is None and tb.what_would_close_it == "not measured: not in the report"
    assert next(f for f in b.figures if f.unit == "s").verdict == "met"


def test_a_registration_that_failed_measures_nothing() -> None:
    b = Bench("bench_registration")
    b.fail("registration", "ValueError: scan_03.e57: E57 file holds no scan")
    registration.record(b, None, None, "ValueError: scan_03.e57: E57 file holds no scan")
    assert all(f.value is None for f in b.figures)
    assert b.finish(None, out=quiet()) == 1


def test_a_checkout_is_dirty_for_code_not_for_the_benchmarks_own_output(tmp_path: Path) -> None:
    def git(*args: str) -> None:
        subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True)

    (tmp_path / "docs" / "bench").mkdir(parents=True)
    (tmp_path / "pkg").mkdir()
    (tmp_path / "docs" / "bench" / "bench_a.json").write_text("{}")
    (tmp_path / "code.py").write_text("x = 1\n")
    git("init", "-q")
    git("add", ".")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "one")
    head = git_commit(tmp_path / "pkg")
    assert head != "unknown" and not head.endswith("+dirty")
    # an earlier benchmark of the same sitting rewrote its JSON: still the same code
    (tmp_path / "docs" / "bench" / "bench_a.json").write_text('{"figures": []}')
    assert git_commit(tmp_path / "pkg") == head
    (tmp_path / "code.py").write_text("x = 2\n")
    assert git_commit(tmp_path / "pkg") == f"{head}+dirty"
