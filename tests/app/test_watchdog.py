"""The launcher's judgement of a hung service: the age of its last heartbeat."""

from __future__ import annotations

from common import codec
from common.messages.system import Health
from phenorover.watchdog import HeartbeatWatch


def beat(pid: int, machine: str = "robot") -> bytes:
    return codec.encode(Health(service="nav", machine=machine, pid=pid, uptime_s=1.0))


def test_a_service_is_hung_once_its_heartbeat_is_older_than_the_limit() -> None:
    w = HeartbeatWatch("robot", hung_after_s=10.0)
    assert w.silent_for(42, 100.0) is None  # never heard: starting, not hung
    w.on_sample(beat(42), 100.0)
    assert w.silent_for(42, 109.9) is None
    assert w.silent_for(42, 110.5) == 10.5
    w.on_sample(beat(42), 111.0)  # heard again (SIGCONT before the limit)
    assert w.silent_for(42, 115.0) is None
    w.forget(42)
    assert w.silent_for(42, 200.0) is None


def test_other_machines_and_garbage_are_no_heartbeat() -> None:
    w = HeartbeatWatch("robot", hung_after_s=5.0)
    w.on_sample(beat(7), 0.0)
    w.on_sample(beat(7, machine="jetson"), 50.0)  # the Jetson's pid 7 is not ours
    w.on_sample(b"\xc1", 50.0)
    assert w.silent_for(7, 50.0) == 50.0
