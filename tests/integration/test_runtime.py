"""The service runtime with real processes on loopback: typed pub/sub, query/reply,
liveliness, bad messages, bulk payloads."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import msgspec
import pytest

from common import keys
from common.client import wait_alive
from common.messages.system import Health
from common.service import STOP_DEADLINE_S
from common.status import query_alive
from common.transport import Bus, RpcError, RpcTimeout
from tests.conftest import Procs
from tests.integration.probe import BLOB, ECHO, RECEIVED, Blob, Echo, Received

PROBE = "tests/integration/probe.py"


def start_pair(procs: Procs, ep: str, bus: Bus, size: int, count: int, tmp: Path) -> None:
    procs.service(PROBE, ep, "--set", "role=listener", log=tmp / "listener.log")
    assert wait_alive(bus.session, {"probe"}, timeout=20)
    procs.service(
        PROBE,
        ep,
        "--set",
        "role=talker",
        "--set",
        f"size={size}",
        "--set",
        f"count={count}",
        "--set",
        "period_s=0.5",
        log=tmp / "talker.log",
    )


def test_typed_pubsub_between_two_services(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    got = client_bus.latest(RECEIVED)
    start_pair(procs, router_endpoint, client_bus, size=1000, count=20, tmp=tmp_path)
    r = got.wait_for(lambda r: r.seq >= 1, timeout=20)
    assert r is not None and r.ok and r.size == 1000


def test_20mb_payload_arrives_whole(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    got = client_bus.latest(RECEIVED)
    size = 20 * 1024 * 1024
    start_pair(procs, router_endpoint, client_bus, size=size, count=6, tmp=tmp_path)
    r = got.wait_for(lambda r: True, timeout=30)
    assert r is not None, "no 20 MB blob arrived"
    assert r.ok and r.size == size


def test_query_reply_and_error_reply(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    procs.service(PROBE, router_endpoint, "--set", "role=talker", log=tmp_path / "t.log")
    assert wait_alive(client_bus.session, {"probe"}, timeout=20)
    deadline = time.monotonic() + 10
    while True:  # the queryable may be declared a moment after the token
        try:
            assert client_bus.call(ECHO, Echo(text="hello"), timeout=2).text == "hello"
            break
        except RpcTimeout:
            assert time.monotonic() < deadline
    with pytest.raises(RpcError, match="'bad' is not allowed"):
        client_bus.call(ECHO, Echo(text="bad"), timeout=5)
    pong = client_bus.call(keys.PING.at(service="probe"), keys.PING.request(text="x"), timeout=5)
    assert pong.service == "probe" and pong.text == "x"


def test_liveliness_seen_and_lost_when_killed(
    procs: Procs, router_endpoint: str, client_bus: Bus
) -> None:
    p = procs.service(PROBE, router_endpoint)
    seen = wait_alive(client_bus.session, {"probe"}, timeout=20).seen
    assert [a.pid for a in seen if a.service == "probe"] == [p.pid]
    p.send_signal(signal.SIGKILL)
    p.wait()
    deadline = time.monotonic() + 15
    while any(a.pid == p.pid for a in query_alive(client_bus.session, timeout=1.0)):
        assert time.monotonic() < deadline, "token of a killed process still alive"


def test_a_service_stuck_in_its_shutdown_dumps_its_stacks_and_exits(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    log = tmp_path / "probe.log"
    p = procs.service(PROBE, router_endpoint, "--set", "hang_on_stop=true", log=log)
    assert wait_alive(client_bus.session, {"probe"}, timeout=20)
    t0 = time.monotonic()
    p.send_signal(signal.SIGTERM)
    rc = p.wait(timeout=10)
    took = time.monotonic() - t0
    assert rc != 0 and STOP_DEADLINE_S <= took < STOP_DEADLINE_S + 3, (rc, took)
    text = log.read_text()
    assert "Timeout" in text and "probe.py" in text, text[-2000:]  # where it hung


def test_bad_messages_are_logged_once_counted_and_dropped(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    log = tmp_path / "listener.log"
    procs.service(PROBE, router_endpoint, "--set", "role=listener", log=log)
    assert wait_alive(client_bus.session, {"probe"}, timeout=20)
    health = client_bus.latest(keys.HEALTH.at(service="probe"))
    assert health.wait_for(lambda h: True, timeout=10) is not None
    enc = msgspec.msgpack.encode
    bad = [
        b"\xc1garbage",  # not msgpack at all
        enc(Echo(text="wrong type")),  # another message type
        enc({"seq": -1, "digest": "", "data": b""}),  # out of range: seq >= 0
    ]
    for payload in bad:
        client_bus.put_raw(BLOB.key, payload)
    h: Health | None = health.wait_for(lambda h: h.decode_errors >= 3, timeout=10)
    assert h is not None, "decode errors not counted"
    assert h.decode_errors == 3 and "test/blob" in h.last_error
    # still serving: a good message gets through after the bad ones
    got = client_bus.latest(RECEIVED)
    pub = client_bus.publisher(BLOB)
    import hashlib

    deadline = time.monotonic() + 10
    while got.get() is None and time.monotonic() < deadline:
        pub.put(Blob(seq=7, digest=hashlib.sha256(b"ok").hexdigest(), data=b"ok"))
        got.wait_for(lambda r: True, timeout=0.5)
    r: Received | None = got.get()
    assert r is not None and r.ok
    lines = [ln for ln in log.read_text().splitlines() if "dropped undecodable" in ln]
    assert len(lines) == 1, lines
    assert "phenorover/test/blob" in lines[0]
