"""The planner service as a process, queried from another: plans, errors naming the
offending field, the cache, and a short request answered while a long one computes."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from common import keys
from common.cli import wait_alive
from common.field import load_field
from common.messages.plan import PlanOptions, PlanRequest, PlanResult
from common.transport import Bus, RpcError
from tests.conftest import Procs


def call(bus: Bus, req: PlanRequest, timeout: float = 120) -> PlanResult:
    deadline = time.monotonic() + 15
    while True:  # the queryable comes up a moment after the liveliness token
        try:
            return bus.call(keys.PLANNER_PLAN, req, timeout=timeout)
        except RpcError as exc:
            if "no reply" not in str(exc) or time.monotonic() > deadline:
                raise


@pytest.fixture
def planner(procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path) -> Bus:
    procs.service(
        "services.planner",
        router_endpoint,
        "--field",
        "spl",
        "--set",
        "warm_up=false",
        log=tmp_path / "planner.log",
    )
    assert wait_alive(client_bus.session, {"planner"}, timeout=20)
    return client_bus


def test_remote_plan_matches_and_is_cached(planner: Bus) -> None:
    layout, _ = load_field("spl")
    t0 = time.monotonic()
    r1 = call(planner, PlanRequest(layout=layout))
    first = time.monotonic() - t0
    assert r1.field == "spl" and len(r1.selected) == 7 and r1.cover.status == "optimal"
    assert r1.cover.cells_covered == r1.cover.cells_coverable
    t0 = time.monotonic()
    r2 = call(planner, PlanRequest(layout=layout, stamp_ns=123))  # same request, new stamp
    assert r2 == r1
    assert time.monotonic() - t0 < first


def test_bad_requests_name_the_field(planner: Bus) -> None:
    with pytest.raises(RpcError, match="exactly one of layout, geojson, name"):
        call(planner, PlanRequest())
    with pytest.raises(RpcError, match="nosuchfield: no such field"):
        call(planner, PlanRequest(name="nosuchfield"))
    with pytest.raises(RpcError, match=r"PlanRequest\.geojson"):
        call(planner, PlanRequest(geojson="{not json"))
    import msgspec

    with pytest.raises(RpcError, match=r"bad request .*coverage_target"):
        raw = msgspec.msgpack.encode({"name": "spl", "options": {"coverage_target": 2.0}})
        replies = planner.session.get(keys.PLANNER_PLAN.key, payload=raw, timeout=10)
        for rep in replies:
            assert rep.err is not None
            raise RpcError(rep.err.payload.to_bytes().decode())


def test_short_request_is_not_held_up_by_a_long_one(planner: Bus) -> None:
    call(planner, PlanRequest(name="spl"))  # now cached; workers warm
    big = PlanRequest(name="engr", options=PlanOptions(visibility="grid", cover="greedy"))
    done: list[float] = []

    def long_request() -> None:
        call(planner, big)
        done.append(time.monotonic())

    th = threading.Thread(target=long_request)
    t0 = time.monotonic()
    th.start()
    time.sleep(0.3)  # let the long request start computing first
    call(planner, PlanRequest(name="spl"))
    quick = time.monotonic()
    th.join(timeout=120)
    assert done, "long request did not finish"
    assert quick < done[0], "the cached answer waited for the long computation"
    assert quick - t0 < 0.3 + 0.5 * (done[0] - t0)
