"""The scan pairs aligned on a Dask cluster (a LocalCluster of two worker
processes): the registration is the local one, to the last bit."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from common.pointcloud import read_e57
from services.register.cli import main
from tests.register.conftest import copy_run
from tests.register.test_truth_invariance import _without_timings

pytest.importorskip("distributed")


def test_pairs_on_the_cluster_give_the_local_registration(
    mission_dir: Path, tmp_path: Path
) -> None:
    run = copy_run(mission_dir, tmp_path)
    here, there = tmp_path / "here", tmp_path / "there"
    assert main([str(run), "--no-figures", "--out", str(here)]) == 0
    assert main([str(run), "--no-figures", "--workers", "2", "--out", str(there)]) == 0
    for x, y in zip(
        read_e57(here / "registered.e57"), read_e57(there / "registered.e57"), strict=True
    ):
        assert np.array_equal(x.pose, y.pose) and np.array_equal(x.points, y.points)
    a = json.loads((here / "report.json").read_text())
    b = json.loads((there / "report.json").read_text())
    assert _without_timings(a) == _without_timings(b)
    assert (here / "registered.laz").read_bytes() == (there / "registered.laz").read_bytes()
