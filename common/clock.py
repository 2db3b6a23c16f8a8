"""Clocks: wall time, or the simulator's published clock.

Services never call ``time.sleep`` or ``time.time`` directly for their loops: they ask
their Clock, so the same code runs in a field (wall clock) or in simulation faster
than real time (sim clock). Every wait takes the service's stop event, so a stop
request ends it at once.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Protocol

from common.messages.sim import SimClock as SimClockMsg

NS = 1_000_000_000


class Clock(Protocol):
    def now_ns(self) -> int:
        """Current time in nanoseconds (wall: since the epoch; sim: since world start)."""
        ...

    def sleep_until_ns(self, t_ns: int, stop: threading.Event) -> bool:
        """Block until ``now_ns() >= t_ns``; False if ``stop`` was set first."""
        ...


def now_s(clock: Clock) -> float:
    return clock.now_ns() / NS


def sleep(clock: Clock, seconds: float, stop: threading.Event) -> bool:
    return clock.sleep_until_ns(clock.now_ns() + int(seconds * NS), stop)


def ticks(clock: Clock, hz: float, stop: threading.Event) -> Iterator[int]:
    """Yield the clock time at ``hz`` until ``stop``; skips ticks it fell behind on
    rather than bursting to catch up (a control loop wants now, not a backlog)."""
    period = int(NS / hz)
    t = clock.now_ns()
    while not stop.is_set():
        yield t
        t += period
        now = clock.now_ns()
        if now > t + period:
            t = now - (now - t) % period
        if not clock.sleep_until_ns(t, stop):
            return


class WallClock:
    def now_ns(self) -> int:
        return time.time_ns()

    def sleep_until_ns(self, t_ns: int, stop: threading.Event) -> bool:
        while True:
            dt = (t_ns - time.time_ns()) / NS
            if dt <= 0:
                return not stop.is_set()
            if stop.wait(min(dt, 0.5)):
                return False


class SimClock:
    """Follows the simulator's ``sim/clock`` messages: feed them to :meth:`update`.

    Time stands still when the simulator stops publishing, so a paused simulator
    pauses every service on it.
    """

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._now = 0
        self.real_time_factor = 1.0
        self._started = threading.Event()

    def update(self, msg: SimClockMsg) -> None:
        with self._cond:
            if msg.sim_ns >= self._now:
                self._now = msg.sim_ns
                self.real_time_factor = msg.real_time_factor
            self._cond.notify_all()
        self._started.set()

    def wait_started(self, timeout: float) -> bool:
        return self._started.wait(timeout)

    def now_ns(self) -> int:
        with self._cond:
            return self._now

    def sleep_until_ns(self, t_ns: int, stop: threading.Event) -> bool:
        with self._cond:
            while self._now < t_ns:
                if stop.is_set():
                    return False
                # wake periodically to notice stop even if the simulator has gone
                self._cond.wait(0.1)
        return not stop.is_set()
