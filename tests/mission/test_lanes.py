"""Lane reservations between two robots' missions over a real router: the second
waits while the first holds a segment it needs, a robot that cannot reach its peer
waits, and a restarted mission holds what it held."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from common.clock import WallClock
from common.field import load_field
from common.messages.nav import Leg
from common.service import Context
from common.transport import Bus
from services.mission.config import LanesConfig
from services.mission.lanes import Lanes
from tests.conftest import client


class GiveUp(Exception):
    pass


def engr_lane(k: int, j0: int, j1: int) -> Leg:
    """A leg along cross lane ``k`` from row-gap lane ``j0`` to ``j1``."""
    _, fld = load_field("engr")
    x, ys = float(fld.cross_lanes_x[k]), fld.row_lanes_y
    return Leg(x0=x, y0=float(ys[j0]), x1=x, y1=float(ys[j1]))


def lanes(bus: Bus, run_dir: Path, peers: list[str]) -> Lanes:
    ctx = Context("mission", "t", bus, WallClock(), logging.getLogger("t"), run_dir, "engr")
    return Lanes(ctx, LanesConfig(peers=peers, retry_s=0.05, answer_timeout_s=0.5))


@pytest.fixture
def two(router_endpoint: str, tmp_path: Path) -> Iterator[tuple[Bus, Bus]]:
    with (
        client(router_endpoint, "mission", namespace="r1") as b1,
        client(router_endpoint, "mission", namespace="r2") as b2,
    ):
        yield b1, b2


class Said(list[str]):
    """What a reservation said, waited on by the test."""

    def __init__(self) -> None:
        super().__init__()
        self._cv = threading.Condition()

    def append(self, text: str) -> None:
        with self._cv:
            super().append(text)
            self._cv.notify_all()

    def wait_for(self, pred: Callable[[list[str]], bool], timeout: float = 30.0) -> bool:
        with self._cv:
            return self._cv.wait_for(lambda: pred(self), timeout)


def reserve_in_thread(ln: Lanes, legs: list[Leg], said: list[str]) -> threading.Thread:
    stop = threading.Event()

    def wait(s: float) -> None:
        if stop.wait(s):
            raise GiveUp

    def run() -> None:
        try:
            ln.reserve(legs, wait, said.append)
        except GiveUp:
            said.append("gave up")

    t = threading.Thread(target=run, daemon=True)
    t.stop = stop  # type: ignore[attr-defined]
    t.start()
    return t


def test_the_second_robot_waits_for_the_segment_the_first_holds(
    two: tuple[Bus, Bus], tmp_path: Path
) -> None:
    l1 = lanes(two[0], tmp_path, ["r2"])
    l2 = lanes(two[1], tmp_path, ["r1"])
    said1: list[str] = []
    first = reserve_in_thread(l1, [engr_lane(3, 1, 3)], said1)
    first.join(30)
    assert not first.is_alive() and "c3.1" in l1.held(), said1
    said2 = Said()
    second = reserve_in_thread(l2, [engr_lane(3, 2, 4)], said2)  # shares c3.2
    assert said2.wait_for(lambda s: any("r1 holds" in x and "c3.2" in x for x in s)), said2
    assert second.is_alive() and not l2.held(), "r2 took a segment r1 holds"
    l1.release_to(*_far_end(l1))  # r1 drives away: keeps only where it stands
    second.join(30)
    assert not second.is_alive() and "c3.2" in l2.held(), said2
    assert not (l1.held() & l2.held())
    assert said2[-1] == "lanes: reserved, driving on"


def _far_end(ln: Lanes) -> tuple[float, float]:
    _, fld = load_field("engr")
    return float(fld.cross_lanes_x[0]), float(fld.row_lanes_y[0])


def test_a_robot_that_cannot_reach_its_peer_waits(two: tuple[Bus, Bus], tmp_path: Path) -> None:
    l1 = lanes(two[0], tmp_path, ["r2", "r9"])  # r9: cut off, or never started
    lanes(two[1], tmp_path, ["r1"])
    said = Said()
    t = reserve_in_thread(l1, [engr_lane(5, 0, 1)], said)
    assert said.wait_for(lambda s: "lanes: waiting, no answer from r9" in s), said
    assert t.is_alive() and not l1.held()
    t.stop.set()  # type: ignore[attr-defined]
    t.join(10)
    assert said[-1] == "gave up" and not l1.held()


def test_a_restarted_mission_holds_what_it_held(
    router_endpoint: str, two: tuple[Bus, Bus], tmp_path: Path
) -> None:
    l1 = lanes(two[0], tmp_path, ["r2"])
    lanes(two[1], tmp_path, ["r1"])
    t = reserve_in_thread(l1, [engr_lane(3, 1, 2)], [])
    t.join(30)
    held = l1.held()
    assert held
    # the same robot's mission started again (another process: here another bus)
    with client(router_endpoint, "mission", namespace="r1") as again:
        assert lanes(again, tmp_path, ["r2"]).held() == held


def test_a_shared_field_needs_a_namespace(client_bus: Bus, tmp_path: Path) -> None:
    from common.config import ConfigError

    with pytest.raises(ConfigError, match="needs a namespace"):
        lanes(client_bus, tmp_path, ["r2"])


def test_what_lies_behind_is_released_at_each_legs_start(
    two: tuple[Bus, Bus], tmp_path: Path
) -> None:
    l1 = lanes(two[0], tmp_path, ["r2"])
    lanes(two[1], tmp_path, ["r1"])
    legs = [engr_lane(3, 0, 3), engr_lane(3, 3, 5)]
    t = reserve_in_thread(l1, legs, [])
    t.join(30)
    assert {"c3.0", "c3.4"} <= l1.held()
    l1.passed(1, legs, legs[1].x0, legs[1].y0)  # at the second leg's start
    held = l1.held()
    assert "c3.0" not in held and "c3.1" not in held  # behind, out of reach
    assert {"c3.2", "c3.3", "c3.4"} <= held  # where it stands, and ahead
