from __future__ import annotations

import threading

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
