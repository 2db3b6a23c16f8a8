"""Bad input, well-typed or not, as real processes see it.

Navigation as a real process on a loopback router, hammered for a few seconds on
every key it reads with random bytes, other message types, non-finite values (dicts
encoded by msgspec, so NaN reaches the wire) and absurd well-typed values. It must
live on, publish only finite and schema-valid poses, count what it refused in
``health/nav``, log at most one traceback per key, follow the real clock through
``sim/clock`` messages from the future, and never command the wheels to move. And
the transport's counting of callbacks and handlers that raise, in one process."""

from __future__ import annotations

import math
import random
import threading
import time
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh

from common import keys
from common.client import wait_alive
from common.clock import NS
from common.codec import decode
from common.config import zenoh_config
from common.messages.base import Imu, LaserScan, Odometry
from common.messages.gnss import GnssHeading, NavSatFix
from common.messages.mission import MissionStart
from common.messages.nav import CancelRoute, FollowRoute, Leg
from common.messages.sim import SimClock
from common.messages.system import Ping, Pong
from common.transport import Bus, RpcError
from tests.conftest import Procs

FUZZ_S = 5.0
CLOCK_PERIOD_S = 0.02  # the fake simulator's clock, 50 Hz at real time
PER_TICK = 10  # fuzz messages per clock tick: ~2500 in all
NAN, INF = math.nan, math.inf

FIX_KEYS = [keys.GNSS_FIX.at(antenna=a).key for a in (1, 2)]
TOPIC_KEYS = {
    keys.BASE_ODOM.key: Odometry,
    FIX_KEYS[0]: NavSatFix,
    FIX_KEYS[1]: NavSatFix,
    keys.GNSS_HEADING.key: GnssHeading,
    keys.BASE_SCAN.key: LaserScan,
    keys.BASE_IMU.key: Imu,
    keys.SIM_CLOCK.key: SimClock,
}
enc = msgspec.msgpack.encode


def absurd(rng: random.Random, key: str, now_ns: int) -> bytes:
    """A message for ``key`` that nav must refuse or survive: garbage, another type,
    a non-finite or out-of-range value, or a well-typed but absurd one (mostly
    stamped ``now_ns``, so it gets past the stamp check to the values)."""
    u = rng.uniform
    weird = rng.choice([NAN, INF, -INF, 1e308, -1e308, 1e-308, 0.0, -0.0])
    kind = rng.randrange(4)
    if kind == 0:
        return rng.randbytes(rng.randrange(0, 64))
    if kind == 1:  # a message of another type, or a bare value
        return rng.choice([enc(Ping(text="x")), enc([1, 2, 3]), enc("odom"), enc(None)])
    typ = TOPIC_KEYS[key]
    if typ is Odometry:
        fields: dict[str, Any] = {"x": u(-1e6, 1e6), "y": 0.0, "yaw": u(-12, 12), "v": u(-99, 99)}
        fields |= {"w": u(-99, 99), "var_v": rng.choice([0.0, 1e-30, 1e30]), "var_w": 0.0}
    elif typ is NavSatFix:
        fields = {"antenna": 1 + (key == FIX_KEYS[1]), "latitude": u(-90, 90)}
        fields |= {"longitude": u(-180, 180), "altitude": u(-1e4, 1e5), "fix_type": 4}
        cov = [rng.choice([0.0, 1e-30, 1e30, -1.0, 1.0]) for _ in range(rng.choice([9, 9, 3]))]
        fields |= {"position_covariance": cov}
    elif typ is GnssHeading:
        fields = {"yaw": u(-12, 12), "yaw_sd": rng.choice([0.0, 1e-300, 1e300]), "valid": True}
        fields |= {"baseline_m": 0.95}
    elif typ is Imu:
        fields = {"roll": u(-12, 12), "pitch": u(-12, 12), "yaw": 0.0, "ax": u(-1e3, 1e3)}
        fields |= {"tilt_var": rng.choice([0.0, 1e-30, 1e30])}
    elif typ is LaserScan:
        data = rng.randbytes(rng.choice([0, 8, 12]))  # mostly not what the shape needs
        fields = {"angle_min": -1.0, "angle_max": 1.0, "angle_increment": 0.01}
        fields |= {"range_min": 0.1, "range_max": 30.0}
        fields |= {"ranges": {"dtype": "<f4", "shape": [rng.randrange(0, 5)], "data": data}}
    else:  # sim/clock: from far in the future, behind, or with a bad rate
        far = rng.choice([2**62, 10**15, 0])
        fields = {"sim_ns": far, "real_time_factor": rng.choice([1.0, 1e6, 0.0, -1.0])}
    fields["stamp_ns"] = rng.choice([now_ns, now_ns, now_ns, 0, 2**62])
    if kind == 2:  # one field made non-finite (or absurd) on the wire
        name = rng.choice([k for k, v in fields.items() if isinstance(v, float)])
        fields[name] = weird
    return enc(fields)


def absurd_request(rng: random.Random) -> bytes:
    leg = {"x0": 0.0, "y0": 0.0, "x1": rng.choice([NAN, INF, 1e8, 1.0]), "y1": 0.0}
    return rng.choice(
        [
            rng.randbytes(rng.randrange(0, 40)),
            enc(MissionStart()),  # another service's command
            enc({"type": "FollowRoute", "route_id": "r", "legs": [leg], "max_speed": NAN}),
            enc({"type": "FollowRoute", "route_id": "r", "legs": [leg]}),
            enc(FollowRoute(route_id="far", legs=[Leg(x0=0, y0=0, x1=9e6, y1=-9e6)])),
            enc(FollowRoute(route_id="none", legs=[])),
            enc(CancelRoute(route_id="r")),
        ]
    )


def finite(obj: Any) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, dict):
        return all(finite(v) for v in obj.values())
    if isinstance(obj, list | tuple):
        return all(finite(v) for v in obj)
    return True


def collect(bus: Bus, key: str) -> list[Any]:
    """Every message on ``key``, decoded schema-free (a NaN would survive to be seen)."""
    got: list[Any] = []
    bus.subscribe_raw(key, msgspec.msgpack.decode, got.append)
    return got


def query(bus: Bus, key: str, payload: bytes) -> bool:
    """Send one raw request and wait for its answer; True if it was an error reply."""
    for reply in bus.session.get(key, payload=payload, timeout=2.0):
        return reply.ok is None
    raise AssertionError(f"no reply on {key}")


class FakeSimClock:
    """The simulator's clock, published from a thread at 50 Hz at real time (a paced
    loop: nothing waits on it)."""

    def __init__(self, bus: Bus) -> None:
        self.pub = bus.publisher(keys.SIM_CLOCK)
        self.sim_ns = 1000 * NS
        self._stop = threading.Event()
        self.tick = threading.Condition()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(CLOCK_PERIOD_S):
            t = self.sim_ns + int(CLOCK_PERIOD_S * NS)
            self.pub.put(SimClock(stamp_ns=t, sim_ns=t))
            with self.tick:
                self.sim_ns = t
                self.tick.notify_all()

    def wait_tick(self, timeout: float = 1.0) -> bool:
        """Block until the clock's next tick (True) or ``timeout`` seconds."""
        with self.tick:
            t = self.sim_ns
            return self.tick.wait_for(lambda: self.sim_ns > t, timeout)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def test_nav_survives_a_fuzz_of_everything_it_reads(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    bus, rng = client_bus, random.Random(11)
    clock = FakeSimClock(bus)
    try:
        fuzz(procs, router_endpoint, bus, rng, clock, tmp_path / "nav.log")
    finally:
        clock.close()


def fuzz(
    procs: Procs, ep: str, bus: Bus, rng: random.Random, clock: FakeSimClock, log: Path
) -> None:
    nav = procs.service("services.nav", ep, "--clock", "sim", "--field", "engr", log=log)
    poses, cmds = collect(bus, keys.NAV_POSE.key), collect(bus, keys.BASE_CMD_VEL.key)
    typed_poses = bus.latest(keys.NAV_POSE)
    health = bus.latest(keys.HEALTH.at(service="nav"))
    assert wait_alive(bus.session, {"nav"}, timeout=30), log.read_text()[-3000:]
    assert typed_poses.wait_for(lambda p: True, timeout=10) is not None

    undecodable = calls = k = 0
    keys_ = list(TOPIC_KEYS)
    t0 = time.monotonic()
    while time.monotonic() < t0 + FUZZ_S:
        key = keys_[k % len(keys_)]
        payload = absurd(rng, key, clock.sim_ns)
        undecodable += _fails(payload, TOPIC_KEYS[key])
        bus.put_raw(key, payload)
        if k % 50 == 0:  # a request: answered (an error or not) before the next one
            req = absurd_request(rng)
            undecodable += _fails(req, keys.NAV_CMD.request)
            query(bus, keys.NAV_CMD.key, req)
            calls += 1
        k += 1
        if k % PER_TICK == 0:  # paced by the fake simulator's clock
            assert clock.wait_tick(), "the fake simulator's clock stopped"
    last_legit = clock.sim_ns

    # still alive and serving, and on the real clock: time went on past the fuzz
    assert nav.poll() is None, log.read_text()[-3000:]
    pong = bus.call(keys.PING.at(service="nav"), Ping(text="still there"), timeout=5)
    assert pong.text == "still there"
    after = typed_poses.wait_for(lambda p: p.stamp_ns > last_legit, timeout=10)
    assert after is not None, "nav's time stopped following the simulator"

    h = health.wait_for(lambda h: h.decode_errors >= undecodable, timeout=10)
    assert h is not None, (undecodable, health.get())
    assert h.decode_errors == undecodable, (h.decode_errors, undecodable)
    # broken LaserScan arrays make nav's scan callback raise: counted, not a log flood
    assert h.callback_errors >= 1, h
    text = log.read_text()
    fuzzed = len(TOPIC_KEYS) + 1
    assert text.count("Traceback") <= fuzzed, text[-3000:]
    assert text.count("dropped undecodable") <= fuzzed

    assert k > 1000 and calls > 20
    assert len(poses) > 50 and all(finite(p) for p in poses)
    assert bus.decode_stats.by_key.get(keys.NAV_POSE.key, 0) == 0  # all valid by schema
    assert max(p["stamp_ns"] for p in poses) <= clock.sim_ns  # no sim/clock from the future
    moving = [c for c in cmds if c.get("linear_x", 0.0) or c.get("angular_z", 0.0)]
    assert not moving, moving[:5]
    # well-typed but absurd: a leg thousands of kilometres off the field is refused
    far = FollowRoute(route_id="far", legs=[Leg(x0=0, y0=0, x1=9e6, y1=-9e6)])
    r = bus.call(keys.NAV_CMD, far, timeout=5)
    assert not r.accepted and "outside field engr" in r.reason, r


def _fails(payload: bytes, typ: Any) -> int:
    """1 if nav's decoder must refuse ``payload`` as ``typ``, else 0."""
    try:
        decode(payload, typ)
    except (msgspec.DecodeError, msgspec.ValidationError):
        return 1
    return 0


def test_callback_and_handler_failures_are_counted_and_logged_once(
    router_endpoint: str, client_bus: Bus, caplog: pytest.LogCaptureFixture
) -> None:
    """A subscriber callback or RPC handler that raises is counted per key, its first
    traceback logged and the rest only counted (they once logged tens of thousands)."""
    session = zenoh.open(zenoh_config("client", [], [router_endpoint]))
    server = Bus(session, "srv")
    topic, rpc = keys.BASE_ODOM, keys.PING.at(service="srv")

    def boom(_: object) -> Pong:
        raise RuntimeError("a bug in a callback")

    try:
        server.subscribe(topic, boom)
        server.serve(rpc, boom)
        pub = client_bus.publisher(topic)
        assert pub.wait_matched(10)
        for k in range(20):
            pub.put(Odometry(stamp_ns=k, x=0, y=0, yaw=0, v=0, w=0))
        for _ in range(5):
            with pytest.raises(RpcError, match="internal error in srv"):
                client_bus.call(rpc, Ping(), timeout=5)
        assert server.callback_stats.by_key[rpc.key] == 5  # counted before the reply
        deadline = time.monotonic() + 10
        while server.callback_stats.by_key.get(topic.key, 0) < 20:
            assert time.monotonic() < deadline, server.callback_stats.by_key
            threading.Event().wait(0.01)
        assert server.callback_stats.total == 25 and server.decode_stats.total == 0
        assert "RuntimeError: a bug in a callback" in server.last_error
        # a service's own counts travel in its heartbeat; a broken reader is left out
        server.report("ekf_rejected", lambda: 7)
        server.report("broken", lambda: 1 // 0)
        assert server.reports() == {"ekf_rejected": 7}
    finally:
        server.close()
        session.close()
    logged = [r for r in caplog.records if "only counted" in r.getMessage()]
    assert len(logged) == 2 and all(r.exc_info for r in logged), logged
