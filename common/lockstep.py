"""Lockstep: the simulated world waits for the services that follow its clock.

Gazebo steps its physics in lockstep with its sensors and PX4's SITL with the
autopilot, so that speed-up and load change how fast a run goes, never what happens
in it. Here the world is one process and the services are others, so each step is a
barrier over Zenoh. Step ``k`` at sim time ``t``:

1. The simulator publishes what its devices sense at ``t``, then the tick
   (``SimClock`` with ``step`` k), whose ``expect`` counts, per publisher and key
   (``"<service>|<key>"``), every message the participants had published when they
   acknowledged step k-1 and every one the simulator has published since.
2. Each participant (:class:`LockstepClock`) waits until it has received every
   expected message on the keys it subscribes to, runs their callbacks in one thread
   in a fixed order (publisher, key, sequence), advances its time to ``t`` and lets
   each of its threads waiting on the clock until ``t`` or earlier run, one at a
   time in the order they first waited, until it waits again. Then it acknowledges
   (``ClockAck``) with its own counts.
3. The simulator, once every participant has acknowledged, takes in the wheel
   commands those acknowledgements count and steps the world.

A message published in answer to step k is therefore taken in at step k+1 by
whoever reads it, whatever the machine's load: the same seed gives the same run. An
RPC from a participant is answered once the callee has finished the caller's step
(:meth:`LockstepClock.serving`), and never while the callee runs one. Nothing of
this reaches a deployment on the wall clock. A participant that hangs is waited for
``deadline_s`` (wall) and then logged and stepped past: the world never freezes.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from common.messages.sim import SimClock as SimClockMsg

log = logging.getLogger(__name__)

Thunk = Callable[[], None]
# how long (wall) the first message of a publisher on a key is waited for, from the
# first step that expected it: a subscription Zenoh has not routed yet never gets it
# (it is then taken as it comes, not waited for), while one that is routed gets it
# in well under a millisecond on loopback, and within this even beside a busy loop
# on every core (where tens of milliseconds are not enough)
FIRST_GRACE_S = 2.0


def attachment(service: str, seq: int) -> bytes:
    """The bytes a lockstep publisher attaches to each message: who sent it, its number."""
    return f"{service}\n{seq}".encode()


def parse_attachment(data: bytes) -> tuple[str, int] | None:
    """(service, sequence) of a lockstep message; None for any other attachment."""
    try:
        service, seq = data.decode().split("\n")
        return service, int(seq)
    except (UnicodeDecodeError, ValueError):
        return None


def caller_attachment(sim_ns: int) -> bytes:
    """What a lockstep caller attaches to its query: its time."""
    return f"at\n{sim_ns}".encode()


def caller_time(data: bytes | None) -> int | None:
    """The time a lockstep caller stamped its query with (None: no stamp)."""
    try:
        what, ns = data.decode().split("\n") if data is not None else ("", "")
        return int(ns) if what == "at" else None
    except (UnicodeDecodeError, ValueError):
        return None


class Inbox:
    """Messages of lockstep publishers, held until the step that expects them; per
    subscription (two subscriptions of one process to a key each get every message)."""

    def __init__(self, intersects: Callable[[str, str], bool]) -> None:
        self._intersects = intersects  # whether two key expressions share a key
        self._cond = threading.Condition()
        self._pending: list[tuple[str, str, int, int, Thunk]] = []
        self._subscribed: list[str] = []  # by subscription number
        self._fresh: list[int] = []  # subscriptions no step has seen yet
        # (subscription, "<service>|<key>") -> highest sequence received; and those a
        # message has come from at all
        self._received: dict[tuple[int, str], int] = {}
        self._seen: set[tuple[int, str]] = set()
        # (subscription, name) never seen -> when (monotonic) a step first expected it
        self._first_expected: dict[tuple[int, str], float] = {}
        self._matches: dict[str, list[int]] = {}

    def subscribed(self, key: str) -> int:
        """A subscription of this process (its number, for :meth:`deliver`): the
        expected messages on keys it intersects are waited for, from the first step
        after it on (what was published before it was declared never reaches it)."""
        with self._cond:
            self._subscribed.append(key)
            self._fresh.append(len(self._subscribed) - 1)
            self._matches.clear()
            return len(self._subscribed) - 1

    def _subs(self, name: str) -> list[int]:
        """The subscriptions a "<service>|<key>" reaches."""
        hit = self._matches.get(name)
        if hit is None:
            key = name.split("|", 1)[1]
            hit = [i for i, s in enumerate(self._subscribed) if self._intersects(s, key)]
            self._matches[name] = hit
        return hit

    def deliver(self, sub: int, key: str, service: str, seq: int, thunk: Thunk) -> None:
        """Hold ``thunk`` (the callback of subscription ``sub`` with its message) until
        its step; a message seen before (a history subscriber's replay) is dropped."""
        name = (sub, f"{service}|{key}")
        with self._cond:
            if seq <= self._received.get(name, 0):
                return
            self._received[name] = seq
            self._seen.add(name)
            self._pending.append((service, key, seq, sub, thunk))
            self._cond.notify_all()

    def take(self, expect: dict[str, int], timeout: float) -> tuple[list[Thunk], list[str]]:
        """Wait up to ``timeout`` s for every expected message on a subscribed key;
        return the callbacks due (expected ones, and those of publishers the step does
        not know yet) in a fixed order, and what never came (``"<service>|<key>"``)."""
        end = time.monotonic() + timeout
        with self._cond:
            wanted = [((i, name), n) for name, n in expect.items() for i in self._subs(name)]
            for (i, name), n in wanted:
                if i in self._fresh:
                    self._received[(i, name)] = max(self._received.get((i, name), 0), n)
            self._fresh.clear()
            now = time.monotonic()
            for sub_name, _ in wanted:
                if sub_name not in self._seen:
                    self._first_expected.setdefault(sub_name, now)

            def missing() -> list[str]:
                # a publisher never heard from is waited for only for a while: Zenoh
                # may not have routed this subscription to it yet (its first messages
                # are then lost)
                now = time.monotonic()
                return [
                    name[1]
                    for name, n in wanted
                    if self._received.get(name, 0) < n
                    and (name in self._seen or now < self._first_expected[name] + FIRST_GRACE_S)
                ]

            while (late := missing()) and (left := end - time.monotonic()) > 0:
                self._cond.wait(min(left, 0.05))
            due: list[tuple[str, str, int, int, Thunk]] = []
            keep: list[tuple[str, str, int, int, Thunk]] = []
            for item in self._pending:
                limit = expect.get(f"{item[0]}|{item[1]}")
                (due if limit is None or item[2] <= limit else keep).append(item)
            self._pending = keep
        due.sort(key=lambda it: it[:4])
        return [it[4] for it in due], sorted(set(late))


class LockstepClock:
    """A participant's clock (the :class:`common.clock.Clock` protocol): time moves
    only with the ticks, and each step's work is done in a fixed order before it is
    acknowledged (see the module). ``ack(sim_ns)`` publishes the acknowledgement."""

    def __init__(self, inbox: Inbox, ack: Callable[[int], None], deadline_s: float) -> None:
        self.inbox = inbox
        self._ack = ack
        self.deadline_s = deadline_s
        self._cond = threading.Condition()
        self._now = 0
        self._started = threading.Event()
        self._waiting: dict[threading.Thread, int] = {}  # thread -> time it waits for
        self._order: dict[threading.Thread, int] = {}  # thread -> when it first waited
        self._turn: threading.Thread | None = None
        self._ticks: queue.SimpleQueue[SimClockMsg] = queue.SimpleQueue()
        self.step_lock = threading.RLock()
        self.acked_ns = -1
        self.late = 0  # steps a message or a thread was waited for in vain
        self._closed = threading.Event()
        self._warned: set[str] = set()
        threading.Thread(target=self._drive, name="lockstep", daemon=True).start()

    # --- the Clock protocol ---
    def now_ns(self) -> int:
        with self._cond:
            return self._now

    def wait_started(self, timeout: float) -> bool:
        return self._started.wait(timeout)

    def sleep_until_ns(self, t_ns: int, stop: threading.Event) -> bool:
        me = threading.current_thread()
        with self._cond:
            self._order.setdefault(me, len(self._order))
            self._waiting[me] = t_ns
            if self._turn is me:
                self._turn = None  # its step's work is done: the next thread's turn
            self._cond.notify_all()
            while self._turn is not me:
                if stop.is_set() or self._closed.is_set():
                    self._waiting.pop(me, None)
                    self._cond.notify_all()
                    return False
                self._cond.wait(0.1)
        return not stop.is_set()

    # --- the ticks ---
    def update(self, msg: SimClockMsg) -> bool:
        """Take a tick (called on Zenoh's thread: queued for the step thread)."""
        self._ticks.put(msg)
        return True

    def close(self) -> None:
        self._closed.set()
        with self._cond:
            self._cond.notify_all()

    def _warn(self, what: str, text: str) -> None:
        self.late += 1
        if what not in self._warned:
            self._warned.add(what)
            log.warning("lockstep: %s (later ones only counted)", text)

    def _drive(self) -> None:
        while not self._closed.is_set():
            try:
                msg = self._ticks.get(timeout=0.5)
            except queue.Empty:
                continue
            with self.step_lock:
                with self._cond:  # the step's messages are taken in at its time
                    self._now = max(self._now, msg.sim_ns)
                thunks, late = self.inbox.take(dict(msg.expect), self.deadline_s)
                if late:
                    self._warn("messages", f"step at {msg.sim_ns / 1e9:.2f} s without {late}")
                for thunk in thunks:
                    thunk()
                self._run_threads(msg.sim_ns)
                with self._cond:
                    self.acked_ns = msg.sim_ns
                    self._cond.notify_all()
            self._started.set()
            self._ack(msg.sim_ns)

    def _run_threads(self, t_ns: int) -> None:
        """Let every thread waiting until ``t_ns`` or earlier run, one at a time."""
        with self._cond:
            self._now = max(self._now, t_ns)
            for _ in range(10_000):  # a thread asking for no time at all, again and again
                due = [th for th, t in self._waiting.items() if t <= t_ns and th.is_alive()]
                if not due or self._closed.is_set():
                    return
                th = min(due, key=lambda x: self._order[x])
                del self._waiting[th]
                self._turn = th
                self._cond.notify_all()
                end = time.monotonic() + self.deadline_s
                while th.is_alive() and self._turn is th and not self._closed.is_set():
                    if time.monotonic() > end:
                        self._warn(th.name, f"thread {th.name} busy for {self.deadline_s:g} s")
                        self._turn = None
                        break
                    self._cond.wait(0.1)

    @contextmanager
    def serving(self, caller_ns: int | None) -> Iterator[None]:
        """Around an RPC handler: once this participant has finished the caller's
        step (``caller_ns``, None for a caller off the clock), never during a step."""
        if caller_ns is not None:
            with self._cond:
                self._cond.wait_for(
                    lambda: self.acked_ns >= caller_ns or self._closed.is_set(), self.deadline_s
                )
        with self.step_lock:
            yield
