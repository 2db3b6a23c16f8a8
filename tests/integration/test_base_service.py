"""The base service as a process on the sim backend: the watchdog and the e-stop as
the wheels see them."""

from __future__ import annotations

import time
from pathlib import Path

from common import keys
from common.client import wait_alive
from common.messages.base import EStop, Twist
from common.messages.sim import SimEncoders, SimWheelCommand
from common.transport import Bus
from tests.conftest import Procs


def test_watchdog_and_estop(
    procs: Procs, router_endpoint: str, client_bus: Bus, tmp_path: Path
) -> None:
    wheels = client_bus.latest(keys.SIM_WHEELS)
    odom = client_bus.latest(keys.BASE_ODOM)
    procs.service(
        "services.base", router_endpoint, "--set", "backend=sim", log=tmp_path / "base.log"
    )
    assert wait_alive(client_bus.session, {"base"}, timeout=20)
    cmd = client_bus.publisher(keys.BASE_CMD_VEL)
    assert cmd.wait_matched(10)

    seen: list[SimWheelCommand] = []
    client_bus.subscribe(keys.SIM_WHEELS, seen.append)
    # a command stream at 10 Hz (the pacing is the test's input, not synchronisation)
    cmd.put(Twist(linear_x=0.4))
    assert wheels.wait_for(lambda w: w.v == 0.4, timeout=2.0)
    n0 = len(seen)
    for _ in range(10):
        cmd.put(Twist(linear_x=0.4))
        time.sleep(0.1)
    assert all(w.v == 0.4 for w in seen[n0 : len(seen) - 2]), "wheels stopped while commanded"
    # then silence: stopped by the 0.25 s watchdog (counted from the last command,
    # 0.1 s before t0, plus one 20 ms control tick)
    t0 = time.monotonic()
    assert wheels.wait_for(lambda w: w.v == 0.0, timeout=2.0)
    # not before the watchdog's time (the wait's own 2 s is the fail-safe)
    assert time.monotonic() - t0 > 0.1

    # an e-stop wins over fresh commands
    estop = client_bus.publisher(keys.BASE_ESTOP)
    estop.put(EStop(asserted=True, reason="test"))
    for _ in range(10):
        cmd.put(Twist(linear_x=0.4))
        time.sleep(0.05)
    last = wheels.get()
    assert last is not None and last.v == 0.0
    status = client_bus.latest(keys.BASE_STATUS)
    assert status.wait_for(lambda s: s.estop, timeout=2.0)

    # encoders integrate into odometry
    enc = client_bus.publisher(keys.SIM_ENCODERS)
    for k in range(11):
        enc.put(SimEncoders(stamp_ns=k * 100_000_000, v=1.0, w=0.0))
    o = odom.wait_for(lambda o: o.x > 0.99, timeout=5.0)
    assert o is not None and abs(o.x - 1.0) < 1e-9 and o.frame_id == "odom"
