"""Which rmw_zenoh_cpp releases services.base.ros2 interoperates with: GIDs computed as
upstream computes them, and the pre-0.2.4 named-field attachment recognised, refused
and reported once per node with the versions named (see services.base.ros2.wire's doc)."""

from __future__ import annotations

import logging
import struct
import threading
from collections.abc import Callable

import pytest
import xxhash
import zenoh
import zenoh.ext as zext

from services.base.ros2 import msgs as ros
from services.base.ros2 import wire
from services.base.ros2.node import Ros2Node
from services.base.ros2.types import ODOMETRY, TWIST

ZID = "4b33868af7b46327b80673b0f621d09b"
NODE_TOKEN = f"@ros2_lv/0/{ZID}/3/3/NN/%/%/husky_node"
ODOM_TOKEN = wire.endpoint_token(
    "MP", 0, ZID, 3, 4, "/husky", "husky_node", "/husky/odom", ODOMETRY.name,
    ODOMETRY.type_hash, wire.Qos(),
)  # fmt: skip
CMD_VEL_TOKEN = wire.endpoint_token(
    "MS", 0, ZID, 0, 1, "/", "base", "/cmd_vel", TWIST.name, TWIST.type_hash, wire.SENSOR_QOS
)

# Each GID as ros2/rmw_zenoh computes it, printed by its own code: simplified_xxhash3.cpp
# at 0.2.10 compiled with the two memcpy's of liveliness_utils.cpp's Entity constructor
# (low64, then high64) on x86-64. The empty string's is xxHash's own XXH3-128 test
# vector, 99aa06d3014798d86001c324468d497f (canonical: high64, low64, big-endian).
UPSTREAM_GIDS = {
    "": "7f498d4624c30160d8984701d306aa99",
    NODE_TOKEN: "6daa0f21b76b9fe98a2186e6cdd518f9",
    ODOM_TOKEN: "592c58c227369d5af0536ac06a719dcf",
    CMD_VEL_TOKEN: "f539ec48459d7c6fdd9bbaf62cbd330e",
}


@pytest.mark.parametrize("token", list(UPSTREAM_GIDS), ids=["empty", "node", "pub", "sub"])
def test_gid_is_upstreams(token: str) -> None:
    gid = wire.gid_of(token)
    assert gid.hex() == UPSTREAM_GIDS[token]
    # the layout, built another way: xxhash's canonical digest is high64 then low64,
    # big-endian; upstream copies low64 then high64 in (little-endian) native order
    canonical = xxhash.xxh3_128(token.encode()).digest()
    high, low = canonical[:8], canonical[8:]
    assert gid == low[::-1] + high[::-1] and len(gid) == wire.GID_SIZE


def test_node_token_is_the_one_hashed() -> None:
    assert wire.node_token(0, ZID, 3, "/", "husky_node") == NODE_TOKEN


def old_attachment(seq: int, stamp_ns: int, gid: bytes) -> bytes:
    """ros2/rmw_zenoh attachment_helpers.cpp at 0.2.3, serialize_to_zbytes: a zenoh-ext
    Serializer fed std::string("sequence_number"), int64, std::string("source_timestamp"),
    int64, std::string("source_gid"), std::array<uint8_t, 16>; zenoh-ext writes a string
    and an array alike, LEB128 length then bytes, and an int64 little-endian."""

    def field(name: str) -> bytes:
        return bytes([len(name)]) + name.encode()

    return (
        field("sequence_number")
        + struct.pack("<q", seq)
        + field("source_timestamp")
        + struct.pack("<q", stamp_ns)
        + field("source_gid")
        + bytes([len(gid)])
        + gid
    )


def test_old_attachment_is_named() -> None:
    gid = bytes(range(16))
    old = old_attachment(7, 1_700_000_000_123_456_789, gid)
    # and as zenoh-python's own zenoh-ext serializer writes the same values
    ref = zext.z_serialize(
        (
            "sequence_number", zext.Int64(7), "source_timestamp",
            zext.Int64(1_700_000_000_123_456_789), "source_gid", gid,
        )
    )  # fmt: skip
    assert old == ref.to_bytes() and len(old) == 77
    for data in (old, old[:20]):  # whole, and cut short
        with pytest.raises(wire.OldAttachment) as err:
            wire.Attachment.decode(data)
        msg = str(err.value)
        assert "\n" not in msg and "0.2.0-0.2.3" in msg and "0.2.4" in msg
    assert isinstance(err.value, wire.WireError)
    # a new-format attachment with any sequence number still decodes
    big = wire.Attachment(2**62, 5, gid)
    assert wire.Attachment.decode(big.encode()) == big


def test_node_reports_an_old_peer_once(
    two_sessions: tuple[zenoh.Session, zenoh.Session], caplog: pytest.LogCaptureFixture
) -> None:
    a, b = two_sessions
    caplog.set_level(logging.WARNING, logger="services.base.ros2.node")
    got: list[tuple[str, float]] = []
    cond = threading.Condition()

    def subscribe(topic: str) -> str:
        def on_twist(t: ros.Twist) -> None:
            with cond:
                got.append((topic, t.linear.x))
                cond.notify_all()

        return sub.subscribe(topic, TWIST, on_twist)

    def arrived(topic: str, x: float) -> Callable[[], bool]:
        return lambda: (topic, x) in got

    def wait(until: Callable[[], bool], timeout: float) -> bool:
        with cond:
            return cond.wait_for(until, timeout=timeout)

    sub = Ros2Node(a, "listener")
    topics = ["cmd_vel", "cmd_vel_2"]
    keys = [subscribe(topic) for topic in topics]
    good = wire.Attachment(1, 0, bytes(16)).encode()
    old = old_attachment(1, 0, bytes(16))
    payload = TWIST.encode(ros.twist(9.0, 0.0))

    # each subscription is matched once a first message on its key gets through
    for topic, key in zip(topics, keys, strict=True):
        for _ in range(100):
            b.put(key, TWIST.encode(ros.twist(0.1, 0.0)), attachment=good)
            if wait(arrived(topic, 0.1), 0.05):
                break
    caplog.clear()
    for key in keys:
        b.put(key, payload, attachment=old)
        b.put(key, payload, attachment=old)
    b.put(keys[0], payload, attachment=b"\x01\x02")  # another reason: its own line
    # one session, one link: these arrive after everything above
    for key in keys:
        b.put(key, TWIST.encode(ros.twist(0.7, 0.0)), attachment=good)
    assert wait(lambda: all(arrived(t, 0.7)() for t in topics), 5.0)
    assert sub.dropped == {keys[0]: 3, keys[1]: 2}
    lines = [r.getMessage() for r in caplog.records if r.name == "services.base.ros2.node"]
    old_lines = [m for m in lines if "0.2.0-0.2.3" in m]
    assert len(old_lines) == 1 and "\n" not in old_lines[0]
    assert "listener" in old_lines[0] and "upgrade ros-jazzy-rmw-zenoh-cpp" in old_lines[0]
    assert len(lines) == 2  # and the bad attachment's
    sub.close()
