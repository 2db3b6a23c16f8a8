"""bench_survey's --keep: a survey run again alone keeps the others' figures, and
the comparisons between kept surveys keep the date and commit they were measured at."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import pytest

from phenorover.eval.results import Bench
from tests.bench import bench_survey as bs
from tests.bench.survey_compare import COMPARISONS, OURS_AGAINST_BASE

# a survey's figures that the comparisons read (cm)
FIGURES = {"overlap_mean_c2c": 2.0, "overlap_mean_target_based": 1.9, "nav_max": 28.0}
FIGURES |= {"hausdorff_mean": 0.5, "hausdorff_sd": 0.6}


def _earlier(path: Path) -> None:
    """A results file of all three surveys, from an earlier commit."""
    b = Bench("bench_survey")
    b.commit = "0ldc0de"
    details: dict[str, Any] = {}
    for name, (manifest, _, _) in bs.SURVEYS.items():
        b.figure(f"{bs.title(name, manifest)}, field engr: nav + C2C", 1.0, "cm")
        details[name] = {**FIGURES, "c2c": 0.6 if name == "sim" else 1.4}
    bs.compare(b, details)
    b.finish(path, details, out=io.StringIO())


@pytest.mark.parametrize("run", ["hil", "paper"])
def test_comparisons_are_kept_only_with_the_surveys_they_compare(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, run: str
) -> None:
    path = tmp_path / "bench_survey.json"
    _earlier(path)

    def measure(bench: Bench, name: str, manifest: Path, *_: Any) -> dict[str, Any]:
        bench.figure(f"{bs.title(name, manifest)}, field engr: nav + C2C", 0.5, "cm")
        return {**FIGURES, "c2c": 2.0}

    monkeypatch.setattr(bs, "measure", measure)
    monkeypatch.setattr("sys.argv", ["bench", "--only", run, "--keep", "--json", str(path)])
    assert bs.main() == 0
    figures = json.loads(path.read_text())["figures"]
    compared = [f for f in figures if f["name"].startswith(COMPARISONS)]
    names = [f["name"] for f in figures]
    assert len(names) == len(set(names)) == len(bs.SURVEYS) + len(COMPARISONS)
    ours = next(f for f in compared if f["name"] == OURS_AGAINST_BASE)
    if run == "hil":  # sim and paper kept: so is what compares them
        assert {f["commit"] for f in compared} == {"0ldc0de"}
        assert ours["value"] == pytest.approx(0.6 / 1.4)
    else:  # the baseline ran again: ours against it is computed anew
        assert "0ldc0de" not in {f["commit"] for f in compared}
        assert ours["value"] == pytest.approx(0.6 / 2.0)
