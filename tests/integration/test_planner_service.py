"""The planner service as a process, queried from another: plans, errors naming the
offending field, the cache, a short request answered while a long one computes, the
workers surviving the warm-up, the field budget and the allowed field folders."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from common import keys
from common.client import wait_alive
from common.field import load_field
from common.messages.plan import PlanOptions, PlanRequest, PlanResult
from common.rpc import until_served
from common.transport import Bus, RpcError
from phenorover.eval.fields import engr_sized
from tests.conftest import REPO, Procs


def call(bus: Bus, req: PlanRequest, timeout: float = 120) -> PlanResult:
    # the queryable comes up a moment after the liveliness token
    return until_served(lambda: bus.call(keys.PLANNER_PLAN, req, timeout=timeout), 15.0)


@pytest.fixture
def planner(
    procs: Procs,
    router_endpoint: str,
    client_bus: Bus,
    tmp_path: Path,
    request: pytest.FixtureRequest,
) -> Bus:
    """The planner service; ``request.param``: extra ``--set`` overrides."""
    sets = ["warm_up=false", *getattr(request, "param", [])]
    args = [a for s in sets for a in ("--set", s)]
    procs.service(
        "services.planner", router_endpoint, "--field", "spl", *args, log=tmp_path / "planner.log"
    )
    assert wait_alive(client_bus.session, {"planner"}, timeout=20)
    return client_bus


def test_remote_plan_matches_and_is_cached(planner: Bus) -> None:
    layout, _ = load_field("spl")
    r1 = call(planner, PlanRequest(layout=layout))
    assert r1.field == "spl" and len(r1.selected) == 7 and r1.cover.status == "optimal"
    assert r1.cover.cells_covered == r1.cover.cells_coverable
    r2 = call(planner, PlanRequest(layout=layout, stamp_ns=123))  # same request, new stamp
    # the first plan again to its stage timings (perf_counter readings a second
    # planning would not repeat): the answer came from the cache
    assert r2 == r1 and r2.timings == r1.timings


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

    health = planner.latest(keys.HEALTH.at(service="planner"))
    th = threading.Thread(target=long_request)
    t0 = time.monotonic()
    th.start()
    # the long request is computing once the planner's heartbeat says so
    beat = health.wait_for(lambda h: h.counters.get("plans_computing", 0) > 0, timeout=30)
    assert beat is not None, "the long request never started"
    started = time.monotonic()
    call(planner, PlanRequest(name="spl"))
    quick = time.monotonic()
    th.join(timeout=120)
    assert done, "long request did not finish"
    assert quick < done[0], "the cached answer waited for the long computation"
    assert quick - started < 0.5 * (done[0] - t0)


@pytest.mark.parametrize("planner", [["warm_up=true"]], indirect=True)
def test_requests_after_the_warm_up_are_answered(planner: Bus) -> None:
    # The warm-up thread started the first worker, which got SIGTERM when that thread
    # ended (PR_SET_PDEATHSIG is per thread): every later request that needed a worker
    # failed with BrokenProcessPool. Two distinct requests need a worker each.
    for cover in ("greedy", "exact"):
        r = call(planner, PlanRequest(name="engr", options=PlanOptions(cover=cover)))
        assert r.field == "engr" and len(r.selected) >= 11
    assert call(planner, PlanRequest(name="spl")).field == "spl"  # the warm-up's, cached


BIG = engr_sized(140, 140)


def test_a_field_beyond_the_budget_is_refused_and_the_planner_keeps_serving(
    planner: Bus,
) -> None:
    with pytest.raises(RpcError, match=r"field 'big': 1,411,200 cells, 19,881 candidates.*budget"):
        call(planner, PlanRequest(layout=BIG))
    assert call(planner, PlanRequest(name="spl")).field == "spl"


def test_field_files_outside_the_allowed_folders_are_refused(planner: Bus, tmp_path: Path) -> None:
    own = tmp_path / "own.toml"
    own.write_text((REPO / "common" / "fields" / "spl.toml").read_text())
    for name in (str(own), "/etc/passwd", "common/fields/../../pyproject.toml"):
        with pytest.raises(RpcError, match=r"PlanRequest\.name: .* outside the planner's field"):
            call(planner, PlanRequest(name=name))
    assert call(planner, PlanRequest(name="common/fields/spl.toml")).field == "spl"
