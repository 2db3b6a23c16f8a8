"""The visibility's chunks on a Dask cluster (a LocalCluster of two worker
processes): the same plan as the local run, byte for byte but for the timings; a
worker killed mid-plan changes nothing; an unreachable scheduler is one line."""

from __future__ import annotations

import os
import signal
from collections.abc import Iterator
from typing import Any

import msgspec
import numpy as np
import pytest

from common.cluster import Cluster, ClusterError
from common.field import ScannerModel
from common.messages.plan import PlanOptions, PlanRequest, PlanResult
from phenorover.cli import main
from phenorover.eval.fields import engr_sized
from services.planner.caster import Cast
from services.planner.cluster import DaskChunks
from services.planner.request import compute, resolve_field
from services.planner.visibility import compute_visibility

pytest.importorskip("distributed")


def _untimed(r: PlanResult) -> bytes:
    """The plan without the seconds each stage took."""
    raw = msgspec.to_builtins(r)
    raw["timings"] = {}
    for part in ("visibility", "cover", "tour"):
        raw[part]["time_s"] = 0.0
    return msgspec.json.encode(raw)


def _field_request(rows: int, plots: int) -> PlanRequest:
    return PlanRequest(
        layout=engr_sized(rows, plots), scanner=ScannerModel(), options=PlanOptions()
    )


# a field too small to be moved from one candidate (lattice): cast chunk by chunk
REQ = _field_request(8, 12)


@pytest.fixture(scope="module")
def cluster() -> Iterator[DaskChunks]:
    with Cluster(workers=2) as c:
        yield DaskChunks(REQ, c)


def test_a_plan_on_the_cluster_is_the_local_plan(cluster: DaskChunks) -> None:
    here = compute(REQ)
    there = compute(REQ, chunks=cluster)
    assert _untimed(there) == _untimed(here)
    assert there.visibility.rays == here.visibility.rays > 0


def test_a_worker_killed_mid_plan_changes_nothing(cluster: DaskChunks) -> None:
    _, field = resolve_field(REQ)
    pids = list(cluster.cluster.client.run(os.getpid).values())

    def killing(
        ranges: list[tuple[int, int]], options: tuple[Any, ...]
    ) -> Iterator[tuple[int, Cast]]:
        it = cluster(ranges, options)
        yield next(it)
        os.kill(pids[0], signal.SIGKILL)  # its chunks run again on the other
        yield from it

    # other options than the first test's: none of its results is kept by the cluster
    here = compute_visibility(field, ScannerModel(), samples=2)
    there = compute_visibility(field, ScannerModel(), samples=2, chunks=killing)
    assert len(here.cand) > 0
    for name in ("cand", "cell", "hits", "range_min"):
        assert np.array_equal(getattr(here, name), getattr(there, name)), name


def test_an_unreachable_scheduler_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(
        ClusterError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1"
    ):
        Cluster("tcp://127.0.0.1:9", timeout_s=1.0)
    assert main(["plan", "engr", "--cluster", "tcp://127.0.0.1:9"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot reach the Dask scheduler" in err[0], err
