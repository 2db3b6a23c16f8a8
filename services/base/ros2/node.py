"""A ROS 2 node over a Zenoh session, speaking rmw_zenoh (:mod:`services.base.ros2.wire`):
what ``ros2 topic list`` on a machine with ``RMW_IMPLEMENTATION=rmw_zenoh_cpp`` sees
as a node with its publishers and subscriptions, and what its nodes exchange data with.

Topics only: ROS 2 services and actions are not spoken (see :mod:`services.base.ros2.wire`).

Callbacks run on Zenoh's threads. A sample without a valid attachment or with a
payload that is not the topic's CDR is dropped (rmw_zenoh drops the first kind too),
counted per topic in ``dropped`` and logged once per topic and reason, one line; a
callback that raises is counted and logged the same way. A sample from a peer on
rmw_zenoh_cpp 0.2.0-0.2.3 (the old attachment) is dropped and counted too, and logged
once per node, one line naming the versions: one old peer is one problem, however
many topics it publishes. Nothing raises into Zenoh.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, Generic, TypeVar

import zenoh

from services.base.ros2 import wire
from services.base.ros2.types import RosType

T = TypeVar("T")
log = logging.getLogger(__name__)

# rmw_zenoh numbers a context's nodes and entities from one counter; a context is a
# session here, so two nodes on one session never share an id
_COUNTERS: dict[str, Iterator[int]] = {}
_COUNTERS_LOCK = threading.Lock()


def _next_id(zid: str) -> int:
    with _COUNTERS_LOCK:
        return next(_COUNTERS.setdefault(zid, itertools.count()))


class Ros2Publisher(Generic[T]):
    """Publishes one topic: CDR payload, rmw_zenoh attachment, system-clock stamps."""

    def __init__(
        self, pub: zenoh.Publisher, rtype: RosType[T], gid: bytes, key: str, token: str
    ) -> None:
        self._pub = pub
        self.rtype = rtype
        self.gid = gid
        self.key = key
        self.token = token
        self._seq = itertools.count(1)
        self._lock = threading.Lock()

    def put(self, msg: T) -> None:
        data = self.rtype.encode(msg)
        with self._lock:  # sequence numbers in the order the samples leave
            att = wire.Attachment(next(self._seq), time.time_ns(), self.gid)
            self._pub.put(data, attachment=att.encode())


class Ros2Node:
    """``Ros2Node(session, "husky_node", namespace="/", domain_id=0)`` declares the
    node's liveliness token; ``publisher`` and ``subscribe`` declare endpoints and
    their tokens. Topic names resolve against ``namespace`` as ROS resolves them."""

    def __init__(
        self,
        session: zenoh.Session,
        node_name: str,
        namespace: str = "/",
        domain_id: int = 0,
        enclave: str = "/",
    ) -> None:
        self.session = session
        self.name, self.namespace, self.domain_id, self.enclave = (
            node_name,
            namespace,
            domain_id,
            enclave,
        )
        self.zid = str(session.info.zid())
        self.node_id = _next_id(self.zid)
        self.token = wire.node_token(
            domain_id, self.zid, self.node_id, namespace, node_name, enclave
        )
        self.dropped: dict[str, int] = {}
        self._logged: set[tuple[str, str]] = set()
        self._lock = threading.Lock()
        self._handles: list[Any] = [session.liveliness().declare_token(self.token)]

    @property
    def dropped_total(self) -> int:
        with self._lock:
            return sum(self.dropped.values())

    def _endpoint(
        self, kind: wire.EntityKind, topic: str, rtype: RosType[Any], qos: wire.Qos
    ) -> tuple[str, str]:
        fq = wire.fully_qualified(self.namespace, topic)
        token = wire.endpoint_token(
            kind,
            self.domain_id,
            self.zid,
            self.node_id,
            _next_id(self.zid),
            self.namespace,
            self.name,
            fq,
            rtype.name,
            rtype.type_hash,
            qos,
            self.enclave,
        )
        return wire.topic_key(self.domain_id, fq, rtype.name, rtype.type_hash), token

    def publisher(
        self, topic: str, rtype: RosType[T], qos: wire.Qos | None = None
    ) -> Ros2Publisher[T]:
        key, token = self._endpoint("MP", topic, rtype, qos or wire.Qos())
        # rmw_zenoh: DROP unless keep-all (which we do not offer); the data first, then
        # the token, so a graph that shows the publisher can receive from it
        pub = self.session.declare_publisher(key, congestion_control=zenoh.CongestionControl.DROP)
        self._handles.append(pub)
        self._handles.append(self.session.liveliness().declare_token(token))
        return Ros2Publisher(pub, rtype, wire.gid_of(token), key, token)

    def subscribe(
        self,
        topic: str,
        rtype: RosType[T],
        callback: Callable[[T], object],
        qos: wire.Qos | None = None,
    ) -> str:
        """Call ``callback(msg)`` for every valid sample on ``topic``; returns the key."""
        key, token = self._endpoint("MS", topic, rtype, qos or wire.Qos())

        def on_sample(sample: zenoh.Sample) -> None:
            try:
                if sample.attachment is None:
                    raise wire.WireError("no attachment")
                wire.Attachment.decode(sample.attachment.to_bytes())
            except wire.OldAttachment as exc:
                self._drop(key, "old rmw_zenoh_cpp", exc, per_node=True)
                return
            except Exception as exc:
                self._drop(key, "bad attachment", exc)
                return
            try:
                msg = rtype.decode(sample.payload.to_bytes())
            except Exception as exc:
                self._drop(key, f"payload is not {rtype.name} CDR", exc)
                return
            try:
                callback(msg)
            except Exception as exc:
                self._drop(key, "callback raised", exc)

        self._handles.append(self.session.declare_subscriber(key, on_sample))
        self._handles.append(self.session.liveliness().declare_token(token))
        return key

    def _drop(self, key: str, what: str, exc: Exception, per_node: bool = False) -> None:
        """Count a dropped sample on ``key``; log the first of each reason, per topic or,
        with ``per_node``, once for the whole node."""
        reason = (str(exc).splitlines() or [""])[0] or type(exc).__name__
        seen = ("", what) if per_node else (key, what)
        with self._lock:
            self.dropped[key] = self.dropped.get(key, 0) + 1
            first = seen not in self._logged
            self._logged.add(seen)
        if not first:
            return
        if per_node:
            log.warning(
                "ros2 node %s: %s (first on %s; every such sample dropped, only counted)",
                self.name,
                reason,
                key,
            )
        else:
            log.warning(
                "ros2 %s: dropped a sample, %s: %s (later ones only counted)", key, what, reason
            )

    def close(self) -> None:
        """Undeclare every endpoint and token (the node leaves the ROS graph)."""
        for h in reversed(self._handles):
            # already gone with its session, or its callback is running now
            with contextlib.suppress(zenoh.ZError, RuntimeError):
                h.undeclare()
        self._handles.clear()
