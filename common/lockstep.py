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

A world started held (``phenorover sim``: until the survey has started) publishes
nothing until it is let run, then first calls the roll: a tick every participant only
acknowledges with its counts, taking nothing in and running nothing. Its first step
then expects every message published while it was held (the survey's start among
them), and nobody has done anything before it: a start that depended on which
service came up first, or on how long the world was held, would not repeat itself.

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

from common.mailbox import Inbox
from common.messages.sim import SimClock as SimClockMsg

log = logging.getLogger(__name__)


class LockstepClock:
    """A participant's clock (the :class:`common.clock.Clock` protocol): time moves
    only with the ticks, and each step's work is done in a fixed order before it is
    acknowledged (see the module). ``ack(sim_ns, roll_call, published)`` publishes the
    acknowledgement; ``counts()`` is what this participant has published so far, and
    ``begin()`` sends what it published before the world began."""

    def __init__(
        self,
        inbox: Inbox,
        ack: Callable[[int, bool, dict[str, int]], None],
        deadline_s: float,
        counts: Callable[[], dict[str, int]] = dict,
        begin: Callable[[], None] = lambda: None,
    ) -> None:
        self.inbox = inbox
        self._ack = ack
        self._counts = counts
        self._begin = begin  # at the roll call or first step: send what waited for it
        self._acked_counts: dict[str, int] = {}
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

    def stamp(self) -> int | None:
        """The time an RPC of this participant carries: None before its first step
        (a caller of a world still held is answered at once, by a callee that has
        done nothing yet either)."""
        with self._cond:
            return self._now if self._started.is_set() else None

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
            if msg.roll_call:
                with self.step_lock:
                    self.inbox.settle()
                    self._begin()
                    counts = self._counts()
                self._ack(msg.sim_ns, True, counts)
                continue
            if msg.sim_ns <= self.acked_ns:  # sent again: acknowledged again, not done again
                self._ack(msg.sim_ns, False, self._acked_counts)
                continue
            with self.step_lock:
                self._begin()
                with self._cond:  # the step's messages are taken in at its time
                    self._now = max(self._now, msg.sim_ns)
                thunks, late = self.inbox.take(dict(msg.expect), self.deadline_s)
                if late:
                    self._warn("messages", f"step at {msg.sim_ns / 1e9:.2f} s without {late}")
                for thunk in thunks:
                    thunk()
                self._run_threads(msg.sim_ns)
                # counted at the step's end, under its lock: what an RPC served after it
                # publishes is counted in the next step's, however late this is sent
                self._acked_counts = self._counts()
                with self._cond:
                    self.acked_ns = msg.sim_ns
                    self._cond.notify_all()
            self._started.set()
            self._ack(msg.sim_ns, False, self._acked_counts)

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
