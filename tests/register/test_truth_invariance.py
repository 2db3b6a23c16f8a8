"""Registration takes no truth: with the simulator's ``.truth.json`` files beside the
scans or without them, it writes the same outputs. Scoring against the truth is the
evaluation's, from those outputs."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from common.pointcloud import read_e57
from phenorover.eval.register.cli import evaluate
from services.register.cli import main
from tests.register.conftest import copy_run

# what a registration measures about itself, different at every run
TIMING = re.compile(rb"registered in [0-9.]+ s")


def _without_timings(report: dict[str, Any]) -> dict[str, Any]:
    report["registration"].pop("time_s")
    report["registration_detail"].pop("time_s")
    report["registration_detail"].pop("timings")
    return report


def test_outputs_are_the_same_with_and_without_truth_files(
    mission_dir: Path, tmp_path: Path
) -> None:
    run = copy_run(mission_dir, tmp_path)
    truths = sorted((tmp_path / "card").glob("*.truth.json"))
    assert truths, "the fixture's scans have no truth files"
    with_truth, without = tmp_path / "with", tmp_path / "without"
    # the default worker processes: each pair is aligned on one thread, so two runs
    # agree to the last bit whichever worker aligned which pair
    assert main([str(run), "--out", str(with_truth)]) == 0
    for t in truths:
        t.unlink()
    assert main([str(run), "--out", str(without)]) == 0

    names = sorted(p.name for p in with_truth.iterdir())
    assert names == sorted(p.name for p in without.iterdir())
    assert "registration_hist.png" in names and "registered.laz" in names
    for name in names:
        a, b = (with_truth / name).read_bytes(), (without / name).read_bytes()
        if name == "registered.e57":
            # E57 gives every file and scan a fresh GUID: compare what it holds
            for x, y in zip(read_e57(with_truth / name), read_e57(without / name), strict=True):
                assert x.name == y.name
                for u, v in ((x.points, y.points), (x.intensity, y.intensity), (x.pose, y.pose)):
                    assert np.array_equal(u, v), name
        elif name == "report.json":
            assert _without_timings(json.loads(a)) == _without_timings(json.loads(b))
        elif name == "report.md":
            assert TIMING.sub(b"", a) == TIMING.sub(b"", b)
        else:
            assert a == b, f"{name} differs with the truth files present"


def test_the_evaluation_scores_the_outputs_against_the_truth(
    mission_dir: Path, tmp_path: Path
) -> None:
    run = copy_run(mission_dir, tmp_path)
    assert main([str(run), "--no-figures"]) == 0
    result, truth = evaluate(run)
    assert truth is not None and truth.scans == len(list((tmp_path / "card").glob("*.e57")))
    for method in ("navigation", "c2c", "target_based"):
        err = truth.methods[method].points.mean
        assert 0 < err < 0.10, (method, err)  # cm, not m
    assert json.loads((run / "eval_register.json").read_text())["truth"]["scans"] == truth.scans
    md = (run / "eval_register.md").read_text()
    assert "Against the simulator's truth" in md and "2.07" in md  # the paper's C2C figure
    assert [r["method"] for r in result["paper"]["table1"]] == ["target_based", "c2c"]
