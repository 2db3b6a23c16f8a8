"""What a lockstep participant receives and sends (:mod:`common.lockstep`): the
inbox that holds each numbered message until the step that expects it, and the
outbox that numbers what it publishes, holding all of it until its first step."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from common.streams import AnyPublisher

Thunk = Callable[[], None]
# how long (wall) the first message of a publisher on a key is waited for, from the
# first step that expected it: a subscription Zenoh has not routed yet never gets it
# (it is then no longer waited for), while one that is routed gets it in well under
# a millisecond on loopback, and within this even beside a busy loop on every core
# (where tens of milliseconds are not enough)
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

    def settle(self) -> None:
        """From the next step on, wait for every expected message on every
        subscription declared so far (lockstep's roll call, before the first step)."""
        with self._cond:
            self._fresh.clear()

    def take(self, expect: dict[str, int], timeout: float) -> tuple[list[Thunk], list[str]]:
        """Wait up to ``timeout`` s for every expected message on a subscribed key;
        return the callbacks due (those the step expects: the rest wait for a step
        that does) in a fixed order, and what never came (``"<service>|<key>"``)."""
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
                # a publisher's message is due once an acknowledgement has counted it:
                # one sent outside a step (an RPC's handler) waits for the next
                limit = expect.get(f"{item[0]}|{item[1]}", 0)
                (due if item[2] <= limit else keep).append(item)
            self._pending = keep
        due.sort(key=lambda it: it[:4])
        return [it[4] for it in due], sorted(set(late))


class Outbox:
    """Numbers what a lockstep publisher sends, per key (its attachment says who sent
    it and its number); with ``hold`` (a participant), holds every message until its
    first step (:meth:`begin`). ``sender``, the name its messages and counts go by, is
    the service's with this process's start: a service restarted numbers from 1
    again, and under its old name every subscriber would take those for replays."""

    def __init__(self, service: str, hold: bool) -> None:
        self.sender = f"{service}@{time.time_ns()}"
        self._lock = threading.Lock()
        self._published: dict[str, int] = {}  # key -> messages put on it
        self._unsent: list[tuple[AnyPublisher, str, bytes]] | None = [] if hold else None

    def counts(self) -> dict[str, int]:
        """How many messages have been sent per key."""
        with self._lock:
            return dict(self._published)

    def send(self, pub: AnyPublisher, key: str, payload: bytes) -> None:
        """Number a message and send it, or hold it until :meth:`begin`. Numbered and
        sent under one lock: a subscriber takes a lower number after a higher one for
        a replay."""
        with self._lock:
            if self._unsent is not None:
                self._unsent.append((pub, key, payload))
            else:
                self._put(pub, key, payload)

    def _put(self, pub: AnyPublisher, key: str, payload: bytes) -> None:
        n = self._published[key] = self._published.get(key, 0) + 1
        pub.put(payload, attachment=attachment(self.sender, n))

    def begin(self) -> None:
        """The participant's first step (or the roll call before it): send what was
        published before, all of it expected in the step after, so that whether a
        service came up before or after another's first words changes nothing."""
        with self._lock:
            unsent, self._unsent = self._unsent or [], None
            for pub, key, payload in unsent:
                self._put(pub, key, payload)
