"""A service stopping while one of its callbacks runs: the callback may find its
publisher gone with the bus, which is the stop, not a fault to log as an error."""

from __future__ import annotations

import threading

import zenoh

from common import keys
from common.config import zenoh_config
from common.messages.system import Health
from common.transport import Bus
from tests.conftest import client


def test_a_callback_caught_by_close_is_not_counted_as_a_failure(router_endpoint: str) -> None:
    started, go, done = threading.Event(), threading.Event(), threading.Event()
    session = zenoh.open(zenoh_config("client", [], [router_endpoint]))
    bus = Bus(session, "stopping")
    out = bus.publisher(keys.HEALTH.at(service="stopping-out"))

    def on_health(h: Health) -> None:
        started.set()
        go.wait(10.0)  # held until the bus has closed under it
        try:
            out.put(h)  # its publisher is gone by now
        finally:
            done.set()

    bus.subscribe(keys.HEALTH.at(service="sender"), on_health)
    try:
        with client(router_endpoint, "sender") as sender:
            pub = sender.publisher(keys.HEALTH.at(service="sender"))
            for _ in range(400):  # until the subscription is matched, 20 s at most
                pub.put(Health(service="sender", machine="m", pid=1, uptime_s=0.0))
                if started.wait(0.05):
                    break
            assert started.is_set(), "the subscription never matched"
        bus.close()
        go.set()
        assert done.wait(10.0)
        assert bus.callback_stats.total == 0
    finally:
        go.set()
        session.close()
