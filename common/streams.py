"""The two ends of a stream: a typed publisher (numbering its messages in lockstep)
and a holder of a subscription's newest message."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import zenoh
import zenoh.ext

from common.codec import encode
from common.keys import Topic

M = TypeVar("M")
# how often a history topic's publisher announces its last sequence number (s)
HEARTBEAT_S = 0.5


def declare_publisher(session: zenoh.Session, topic: Topic[M], numbered: bool) -> Any:
    """Zenoh's publisher for ``topic`` by its delivery class (:class:`common.keys.Topic`):
    bulk BLOCK at low priority, control DROP at real-time priority, the rest DROP;
    ``numbered`` (a message a lockstep step waits for) always BLOCK, since a dropped
    one would be waited for. A history topic gets Zenoh's advanced publisher, cached
    and sequenced: subscribers recover what a cut link lost (the heartbeat tells them
    within a second of the link's return)."""
    if topic.bulk:
        cc, prio = zenoh.CongestionControl.BLOCK, zenoh.Priority.DATA_LOW
    elif topic.control:
        cc, prio = zenoh.CongestionControl.DROP, zenoh.Priority.REAL_TIME
    else:
        cc, prio = zenoh.CongestionControl.DROP, zenoh.Priority.DATA
    if numbered:
        cc = zenoh.CongestionControl.BLOCK
    if not topic.history:
        return session.declare_publisher(topic.key, congestion_control=cc, priority=prio)
    return zenoh.ext.declare_advanced_publisher(
        session,
        topic.key,
        congestion_control=cc,
        priority=prio,
        cache=zenoh.ext.CacheConfig(max_samples=topic.history),
        sample_miss_detection=zenoh.ext.MissDetectionConfig(
            heartbeat=HEARTBEAT_S, sporadic_heartbeat=None
        ),
        publisher_detection=True,
    )


class Latest(Generic[M]):
    """Holds the newest message of a subscription; ``wait_for`` blocks on a predicate."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._value: M | None = None
        self.count = 0

    def put(self, msg: M) -> None:
        with self._cond:
            self._value = msg
            self.count += 1
            self._cond.notify_all()

    def get(self) -> M | None:
        with self._cond:
            return self._value

    def wait_for(self, pred: Callable[[M], bool], timeout: float) -> M | None:
        """The first value (current or future) satisfying ``pred``, or None on timeout."""
        result: list[M] = []

        def ok() -> bool:
            v = self._value
            if v is not None and pred(v):
                result.append(v)
                return True
            return False

        with self._cond:
            self._cond.wait_for(ok, timeout)
        return result[0] if result else None


def key_intersects(a: str, b: str) -> bool:
    """Whether key expressions ``a`` and ``b`` share a key."""
    return bool(zenoh.KeyExpr(a).intersects(zenoh.KeyExpr(b)))


AnyPublisher = zenoh.Publisher | zenoh.ext.AdvancedPublisher


class Publisher(Generic[M]):
    def __init__(
        self,
        pub: AnyPublisher,
        topic: Topic[M],
        send: Callable[[AnyPublisher, str, bytes], None] | None = None,
    ) -> None:
        self._pub = pub
        self.topic = topic
        self._send = send  # in lockstep: numbers each message (the bus's), or holds it

    def wait_matched(self, timeout: float) -> bool:
        """Block until some subscriber matches this key (True) or ``timeout`` s pass."""
        deadline = time.monotonic() + timeout
        # an advanced publisher (history topics) has no matching status: it caches
        while not getattr(getattr(self._pub, "matching_status", None), "matching", True):
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.02)
        return True

    def put(self, msg: M) -> None:
        if type(msg) is not self.topic.type:
            raise TypeError(
                f"{self.topic.key} carries {self.topic.type.__name__}, not {type(msg).__name__}"
            )
        if self._send is None:
            self._pub.put(encode(msg))
        else:
            self._send(self._pub, self.topic.key, encode(msg))
