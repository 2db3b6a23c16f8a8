from __future__ import annotations

import itertools
import math
import threading

import pytest

from common.clock import NS, SimClock, WallClock, sleep, ticks
from common.messages.sim import SimClock as SimClockMsg


def test_sim_clock_sleep_wakes_on_published_time() -> None:
    clock = SimClock()
    stop = threading.Event()
    done = threading.Event()

    def sleeper() -> None:
        if clock.sleep_until_ns(2 * NS, stop):
            done.set()

    t = threading.Thread(target=sleeper)
    t.start()
    clock.update(SimClockMsg(sim_ns=NS))
    assert not done.wait(0.2)
    clock.update(SimClockMsg(sim_ns=2 * NS, real_time_factor=10.0))
    assert done.wait(2.0)
    t.join()
    assert clock.now_ns() == 2 * NS and clock.real_time_factor == 10.0


def test_sim_clock_never_runs_backwards() -> None:
    clock = SimClock()
    clock.update(SimClockMsg(sim_ns=5))
    clock.update(SimClockMsg(sim_ns=3))
    assert clock.now_ns() == 5


def test_stop_ends_a_sleep_at_once() -> None:
    stop = threading.Event()
    stop.set()
    assert not sleep(WallClock(), 60.0, stop)
    assert not SimClock().sleep_until_ns(NS, stop)


def test_ticks_follow_sim_time_without_bursting() -> None:
    clock = SimClock()
    stop = threading.Event()
    seen: list[int] = []

    def loop() -> None:
        for t in ticks(clock, 10.0, stop):
            seen.append(t)
            if len(seen) == 3:
                stop.set()

    th = threading.Thread(target=loop)
    th.start()
    for k in range(1, 40):
        if not th.is_alive():
            break
        clock.update(SimClockMsg(sim_ns=k * NS // 20))
        th.join(0.02)
    stop.set()
    th.join(2.0)
    assert seen[:3] == [0, NS // 10, 2 * NS // 10]


class FakeWall:
    """A wall clock (monotonic seconds) the test moves by hand."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def run_sim(clock: SimClock, wall: FakeWall, start_ns: int, steps: int, rtf: float = 1.0) -> int:
    """Feed ``steps`` messages of a simulator publishing every 20 ms of sim time at
    ``rtf``, from ``start_ns``; returns the sim time after the last one."""
    t = start_ns
    for _ in range(steps):
        clock.update(SimClockMsg(sim_ns=t, real_time_factor=rtf))
        t += NS // 50
        wall.t += 0.02 / rtf
    return t - NS // 50


def test_a_message_from_the_future_is_refused_and_time_follows_the_real_sim() -> None:
    wall = FakeWall()
    clock = SimClock(wall=wall)
    last = run_sim(clock, wall, 10 * NS, 50, rtf=4.0)
    assert clock.now_ns() == last and clock.refused == 0
    assert not clock.update(SimClockMsg(sim_ns=last + 3600 * NS, real_time_factor=4.0))
    assert clock.now_ns() == last and clock.refused_by_kind == {"ahead": 1}
    # the real simulator goes on, and so does time; the bogus stamp changed nothing
    last = run_sim(clock, wall, last + NS // 50, 50, rtf=4.0)
    assert clock.now_ns() == last and clock.refused == 1
    assert "ahead" in clock.last_refusal


def test_the_first_message_is_accepted_whatever_its_time() -> None:
    clock = SimClock(wall=FakeWall())
    assert clock.update(SimClockMsg(sim_ns=10**15))
    assert clock.now_ns() == 10**15 and clock.wait_started(0.0)


def test_a_follower_cut_off_for_a_while_takes_the_time_it_missed() -> None:
    """The allowance grows with the wall time waited: a link that comes back after
    10 s at 10x brings a 100 s jump, which is the world moving on, not a bad peer."""
    wall = FakeWall()
    clock = SimClock(wall=wall)
    last = run_sim(clock, wall, 0, 10, rtf=10.0)
    wall.t += 10.0
    assert clock.update(SimClockMsg(sim_ns=last + 100 * NS, real_time_factor=10.0))
    assert clock.now_ns() == last + 100 * NS and clock.refused == 0


def test_a_restarted_simulator_one_second_behind_stops_time_until_it_catches_up() -> None:
    wall = FakeWall()
    clock = SimClock(wall=wall)
    last = run_sim(clock, wall, 0, 500)  # 10 s of sim time
    resumed = last - NS  # the snapshot it restarted from is 1 s old
    seen = []
    t = resumed
    for _ in range(100):  # 2 s of the restarted simulator
        clock.update(SimClockMsg(sim_ns=t))
        seen.append(clock.now_ns())
        t += NS // 50
        wall.t += 0.02
    # time stood still for the lag (never backwards), then followed the simulator
    assert all(b >= a for a, b in itertools.pairwise(seen))
    still = [s for s in seen if s == last]
    assert 49 <= len(still) <= 51, len(still)  # 1 s of 20 ms steps
    assert seen[-1] == t - NS // 50
    assert clock.refused_by_kind.get("behind", 0) == 50
    assert "ahead" not in clock.refused_by_kind


def test_a_sleeper_waits_only_as_long_as_the_lag() -> None:
    wall = FakeWall()
    clock = SimClock(wall=wall)
    last = run_sim(clock, wall, 0, 100)
    stop = threading.Event()
    woke = threading.Event()
    target = last + NS // 10

    def sleeper() -> None:
        if clock.sleep_until_ns(target, stop):
            woke.set()

    th = threading.Thread(target=sleeper)
    th.start()
    t, sent = last - NS // 2, 0  # restarted 0.5 s behind
    while clock.now_ns() < target:
        clock.update(SimClockMsg(sim_ns=t))
        t, sent = t + NS // 50, sent + 1
        assert sent < 1000
    # 0.5 s of lag plus the 0.1 s slept: 30 steps of 20 ms, not one more
    assert sent == 31 and clock.now_ns() == target
    assert woke.wait(2.0)
    th.join(2.0)


@pytest.mark.parametrize("rtf", [0.0, -1.0, math.nan, math.inf])
def test_a_bad_real_time_factor_is_refused(rtf: float) -> None:
    clock = SimClock(wall=FakeWall())
    assert clock.update(SimClockMsg(sim_ns=NS, real_time_factor=2.0))
    assert not clock.update(SimClockMsg(sim_ns=2 * NS, real_time_factor=rtf))
    assert clock.now_ns() == NS and clock.real_time_factor == 2.0
    assert clock.refused_by_kind == {"bad": 1}
