"""Clocks: wall time, or the simulator's published clock.

Services never call ``time.sleep`` or ``time.time`` directly for their loops: they ask
their Clock, so the same code runs in a field (wall clock) or in simulation faster
than real time (sim clock). Every wait takes the service's stop event, so a stop
request ends it at once.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Protocol

from common.messages.sim import SimClock as SimClockMsg

NS = 1_000_000_000
log = logging.getLogger(__name__)


class Clock(Protocol):
    def now_ns(self) -> int:
        """Current time in nanoseconds (wall: since the epoch; sim: since world start)."""
        ...

    def sleep_until_ns(self, t_ns: int, stop: threading.Event) -> bool:
        """Block until ``now_ns() >= t_ns``; False if ``stop`` was set first."""
        ...

    def wait_started(self, timeout: float) -> bool:
        """Whether the clock tells time yet, waiting up to ``timeout`` seconds for it: a
        sim clock reads 0 until its first message, and a deadline taken then is no
        deadline."""
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

    def wait_started(self, timeout: float) -> bool:
        return True

    def sleep_until_ns(self, t_ns: int, stop: threading.Event) -> bool:
        while True:
            dt = (t_ns - time.time_ns()) / NS
            if dt <= 0:
                return not stop.is_set()
            if stop.wait(min(dt, 0.5)):
                return False


#: How far (sim seconds) a ``sim/clock`` message may lead the follower's time beyond
#: what the simulator can have run since the last accepted message (twice its
#: real-time factor times the wall time since then). The simulator publishes every
#: physics step (20 ms of sim time), so 5 s is 250 lost messages in a row, far more
#: than a loopback link drops; while a time from another run or a corrupt stamp is
#: off by minutes to years. A follower whose link was cut is not locked out: its
#: allowance grows with the wall time it waited.
MAX_JUMP_S = 5.0


class SimClock:
    """Follows the simulator's ``sim/clock`` messages: feed them to :meth:`update`.

    Time stands still when the simulator stops publishing, so a paused simulator
    pauses every service on it. It never runs backwards, and it refuses (does not
    apply) a message that is implausible:

    - a ``real_time_factor`` that is not finite and > 0, or a negative ``sim_ns``;
    - a time behind the current one: ignored, so a simulator restarted from a
      snapshot (which resumes up to ~1 s behind) makes time stand still until it
      catches up, for as long as the lag and no longer;
    - a time more than ``max_jump_s + 2 * real_time_factor * wall seconds since the
      last accepted message`` ahead: a world that far ahead is not the one being
      followed (one such message froze every service until time caught up with it).

    The first message after start is accepted whatever its time. Refusals are counted
    in :attr:`refused` and logged once per kind. ``wall`` (seconds, monotonic) is
    injectable for tests.
    """

    def __init__(
        self, max_jump_s: float = MAX_JUMP_S, wall: Callable[[], float] = time.monotonic
    ) -> None:
        self._cond = threading.Condition()
        self._now = 0
        self.real_time_factor = 1.0
        self._started = threading.Event()
        self.max_jump_s = max_jump_s
        self._wall = wall
        self._accepted_at: float | None = None  # wall time of the last accepted message
        self.refused = 0
        self.refused_by_kind: dict[str, int] = {}
        self.last_refusal = ""

    def _refusal(self, msg: SimClockMsg) -> tuple[str, str] | None:
        """(kind, reason) when ``msg`` must not be applied, else None (holds the lock)."""
        rtf = msg.real_time_factor
        if not (math.isfinite(rtf) and rtf > 0) or msg.sim_ns < 0:
            return "bad", f"sim_ns {msg.sim_ns}, real_time_factor {rtf!r}"
        if self._accepted_at is None:
            return None
        if msg.sim_ns < self._now:
            return "behind", f"{(self._now - msg.sim_ns) / NS:.3f} s behind"
        waited = max(0.0, self._wall() - self._accepted_at)
        allowed = self.max_jump_s + 2.0 * self.real_time_factor * waited
        ahead = (msg.sim_ns - self._now) / NS
        if ahead > allowed:
            return "ahead", f"{ahead:.3f} s ahead (at most {allowed:.3f} s allowed)"
        return None

    def update(self, msg: SimClockMsg) -> bool:
        """Apply one ``sim/clock`` message; False when it was refused (see the class)."""
        with self._cond:
            refusal = self._refusal(msg)
            if refusal is None:
                self._now = max(self._now, msg.sim_ns)
                self.real_time_factor = msg.real_time_factor
                self._accepted_at = self._wall()
                self._cond.notify_all()
                self._started.set()
                return True
            kind, reason = refusal
            self.refused += 1
            first = kind not in self.refused_by_kind
            self.refused_by_kind[kind] = self.refused_by_kind.get(kind, 0) + 1
            self.last_refusal = f"sim/clock {kind}: {reason}"
        if first:
            # expected (once) after a simulator restart; anything else is a bad peer
            level = logging.INFO if kind == "behind" else logging.WARNING
            log.log(level, "refused a sim/clock message, %s (later ones only counted)", reason)
        return False

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
