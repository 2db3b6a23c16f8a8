"""Typed publish/subscribe/query over one Zenoh session.

Only this module, the two it is made of (:mod:`common.streams`, :mod:`common.rpc`)
and the service runner touch Zenoh's API. Messages are msgpack encoded by msgspec
(:mod:`common.codec`). A message that fails to decode is logged once per key with the
reason, counted, and dropped: a bad peer cannot crash a service. A subscriber
callback or RPC handler that raises is treated the same way (first traceback per key
logged, every one counted): a stream of bad input must show in ``health/<service>``,
not as a log of tens of thousands of tracebacks.
"""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

import zenoh
import zenoh.ext

from common.codec import DecodeStats, decode, encode
from common.keys import ALIVE_ALL, Rpc, Topic, participant
from common.lockstep import LockstepClock
from common.mailbox import Inbox, Outbox, caller_attachment, caller_time, parse_attachment
from common.rpc import RequestError, RpcError, RpcTimeout, answer, first_reply, good_replies
from common.streams import Latest, Publisher, declare_publisher, key_intersects

__all__ = ["Bus", "Latest", "Publisher", "RequestError", "RpcError", "RpcTimeout", "key_intersects"]

M = TypeVar("M")
Q = TypeVar("Q")
R = TypeVar("R")

log = logging.getLogger(__name__)


class Bus:
    """A service's typed view of its Zenoh session.

    Subscription callbacks run on Zenoh's threads: keep them short (store, notify).
    RPC handlers run on a small thread pool so a slow request does not block others.
    ``decode_stats`` counts what failed to decode, ``callback_stats`` what decoded
    but made its callback or handler raise; both per key. With a ``namespace`` (a
    robot's, :mod:`common.keys`) every topic and endpoint but the site's is that
    robot's: the service's own and those it talks to alike.
    """

    def __init__(
        self, session: zenoh.Session, name: str, rpc_workers: int = 4, namespace: str = ""
    ) -> None:
        self.session = session
        self.name = name
        self.namespace = namespace
        # the name by which lockstep and the launcher tell this robot's service apart
        self.participant = participant(name, namespace)
        self.decode_stats = DecodeStats()
        self.callback_stats = DecodeStats()
        self._reports: dict[str, Callable[[], int]] = {}
        self._handles: list[Any] = []
        self._closing = False
        self._pool = ThreadPoolExecutor(max_workers=rpc_workers, thread_name_prefix=f"{name}-rpc")
        # lockstep with the simulator (common/lockstep.py): off unless use_lockstep
        self._inbox: Inbox | None = None
        self._clock: LockstepClock | None = None
        self._outbox: Outbox | None = None

    def use_lockstep(self, inbox: Inbox, clock: LockstepClock | None = None) -> None:
        """Take part in the simulator's lockstep: number every message put (and send
        it with congestion control BLOCK: a dropped one would be waited for), hold
        each numbered message received until its step (``inbox``), and with
        ``clock`` (a participant) hold what it puts until its first step, answer RPCs
        between steps and stamp calls with the caller's time. Call before declaring
        publishers and subscribers."""
        self._inbox, self._clock = inbox, clock
        self._outbox = Outbox(self.participant, hold=clock is not None)

    @property
    def sender(self) -> str:
        """The name this process's lockstep messages and counts go by."""
        return self.participant if self._outbox is None else self._outbox.sender

    def counts(self) -> dict[str, int]:
        """How many messages have been put per key, in lockstep."""
        return {} if self._outbox is None else self._outbox.counts()

    def begin(self) -> None:
        """In lockstep, send what was put before the participant's first step."""
        if self._outbox is not None:
            self._outbox.begin()

    def _dropped(self, key: str, exc: Exception) -> None:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if self.decode_stats.record(key, reason):
            log.warning("dropped undecodable message on %s: %s", key, reason)

    def _failed(self, key: str, what: str) -> None:
        """Count a callback or handler that raised (call from its ``except``): the
        first failure per key is logged with its traceback, later ones only counted,
        so a stream of bad input cannot flood the log."""
        exc = sys.exc_info()[1]
        if self._closing and isinstance(exc, zenoh.ZError):  # a callback caught by close()
            log.debug("%s for %s ended with the bus: %s", what, key, exc)
            return
        reason = (str(exc).splitlines() or [""])[0] or type(exc).__name__
        if self.callback_stats.record(key, f"{what} raised {type(exc).__name__}: {reason}"):
            log.exception("%s for %s failed (later failures on it are only counted)", what, key)

    def report(self, name: str, read: Callable[[], int]) -> None:
        """Add a count to this service's ``health/<service>`` heartbeat
        (``Health.counters[name]``): ``read`` is called from the heartbeat's thread,
        so it must only read (an int attribute is fine)."""
        self._reports[name] = read

    def reports(self) -> dict[str, int]:
        """Every reported count now; one whose ``read`` raises is left out."""
        out = {}
        for name, read in list(self._reports.items()):
            with contextlib.suppress(Exception):
                out[name] = int(read())
        return out

    @property
    def last_error(self) -> str:
        """The latest failure of either kind, one line ("" before any)."""
        d, c = self.decode_stats, self.callback_stats
        return d.last_error if d.last_ns >= c.last_ns else c.last_error

    def publisher(self, topic: Topic[M], in_step: bool = True) -> Publisher[M]:
        """A publisher on ``topic``; in lockstep its messages are numbered unless
        ``in_step`` is False (a heartbeat on the wall clock, which no step waits for)."""
        topic = topic.within(self.namespace)
        outbox = self._outbox if in_step else None
        pub = declare_publisher(self.session, topic, outbox is not None)
        self._handles.append(pub)
        return Publisher(pub, topic, None if outbox is None else outbox.send)

    def subscribe(
        self, topic: Topic[M], callback: Callable[[M], object], immediate: bool = False
    ) -> None:
        """Call ``callback`` with each decoded message on ``topic`` (a key or pattern);
        in lockstep at the step that expects it unless ``immediate``."""
        topic = topic.within(self.namespace)
        self.subscribe_raw(
            topic.key,
            lambda data: decode(data, topic.type),
            callback,
            history=topic.history > 0,
            immediate=immediate,
        )

    def latest(self, topic: Topic[M]) -> Latest[M]:
        holder: Latest[M] = Latest()
        self.subscribe(topic, holder.put)
        return holder

    def serve(self, rpc: Rpc[Q, R], handler: Callable[[Q], R], stepped: bool = True) -> None:
        """Answer queries on ``rpc.key`` with ``handler(request)``; in lockstep between
        steps, unless not ``stepped`` (an answer no step changes: asked mid-step too).

        A request that fails to decode, or a handler raising RequestError, gets an
        error reply with a one-line reason; other exceptions are logged and answered
        as internal errors. The service keeps serving either way."""
        rpc = rpc.within(self.namespace)

        def work(query: zenoh.Query) -> None:
            serving = None
            if self._clock is not None and stepped:
                tag = query.attachment
                serving = self._clock.serving(caller_time(tag.to_bytes() if tag else None))
            answer(query, rpc, handler, self.name, self._dropped, self._failed, serving)

        def on_query(query: zenoh.Query) -> None:
            self._pool.submit(work, query)

        self._handles.append(self.session.declare_queryable(rpc.key, on_query))

    def call(self, rpc: Rpc[Q, R], request: Q, timeout: float = 5.0) -> R:
        """Send ``request`` and return the first reply.

        Raises RpcError with the service's reason on an error reply, RpcTimeout when
        nobody answers within ``timeout`` seconds; in lockstep, within the lockstep's
        deadline when that is longer: how long an answer takes in wall time is the
        machine's load, which must not change what happens (a timed-out call is
        retried and logged), and a callee that hangs is the lockstep's to name.
        """
        rpc = rpc.within(self.namespace)
        at = None
        if self._clock is not None:
            stamp = self._clock.stamp()
            at = None if stamp is None else caller_attachment(stamp)
            timeout = max(timeout, self._clock.deadline_s)
        replies = self.session.get(rpc.key, payload=encode(request), timeout=timeout, attachment=at)
        return first_reply(replies, rpc, timeout)

    def gather(self, rpc: Rpc[Q, R], request: Q, timeout: float = 2.0) -> list[R]:
        """Send ``request`` to every service answering ``rpc`` (a key with wildcards,
        such as ``rpc/*/config``) and return each good reply, as they came within
        ``timeout`` seconds; error and undecodable replies are left out."""
        rpc = rpc.within(self.namespace)
        replies = self.session.get(
            rpc.key,
            payload=encode(request),
            timeout=timeout,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
        )
        return good_replies(replies, rpc, self._dropped)

    def watch_alive(self, callback: Callable[[str, bool], object]) -> None:
        """Call ``callback(token_key, alive)`` for every service's liveliness token
        (``alive/...``), those declared before this call included: alive False when a
        token goes, which is within milliseconds of its process dying (the kernel
        closes its connection), long before any heartbeat or lease would tell."""
        self.watch(ALIVE_ALL, callback)

    def watch(self, key: str, callback: Callable[[str, bool], object]) -> None:
        """:meth:`watch_alive` for the liveliness tokens matching ``key``."""

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                callback(str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT)
            except Exception:
                self._failed(key, "liveliness callback")

        self._handles.append(
            self.session.liveliness().declare_subscriber(key, on_sample, history=True)
        )

    def put_raw(self, key: str, data: bytes) -> None:
        """Publish raw bytes on a key outside the message table (a ROS 2 bridge's CDR
        topics), or malformed data in tests."""
        self.session.put(key, data)

    def subscribe_raw(
        self,
        key: str,
        decoder: Callable[[bytes], M],
        callback: Callable[[M], object],
        history: bool = False,
        immediate: bool = False,
    ) -> None:
        """Subscribe to a foreign encoding: ``decoder`` raises on bad bytes (any
        exception), which is logged once, counted and dropped like a bad message. A
        ``callback`` that raises is counted in ``callback_stats`` and its first
        traceback per key logged; its return value is ignored. With ``history``, the
        publishers' caches are asked for what was sent before this subscription and
        for what a cut link lost (each message once)."""

        inbox = None if immediate else self._inbox
        sub = -1 if inbox is None else inbox.subscribed(key)

        def run(msg: M) -> None:
            try:
                callback(msg)
            except Exception:
                self._failed(key, "subscriber callback")

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                msg = decoder(sample.payload.to_bytes())
            except Exception as exc:
                self._dropped(key, exc)
                return
            tag = None if inbox is None or sample.attachment is None else sample.attachment
            sent = None if tag is None else parse_attachment(tag.to_bytes())
            if inbox is not None and sent is not None:
                inbox.deliver(sub, str(sample.key_expr), sent[0], sent[1], lambda: run(msg))
            else:
                run(msg)

        if history:
            self._handles.append(
                zenoh.ext.declare_advanced_subscriber(
                    self.session,
                    key,
                    on_sample,
                    history=zenoh.ext.HistoryConfig(detect_late_publishers=True),
                    recovery=zenoh.ext.RecoveryConfig(periodic_queries=None, heartbeat=True),
                    subscriber_detection=True,
                )
            )
        else:
            self._handles.append(self.session.declare_subscriber(key, on_sample))

    def close(self) -> None:
        self._closing = True  # a callback still running may find its publisher gone
        for h in reversed(self._handles):
            # RuntimeError: a callback of this handle is running right now (a token
            # going as its service stops); closing the session drops it all the same
            with contextlib.suppress(zenoh.ZError, RuntimeError):
                h.undeclare()
        self._handles.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)
