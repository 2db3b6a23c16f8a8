"""The wire simulator runs the same receiver as the gnss ``sim`` backend: for the same
truth stream, faults included, its TCP bytes are the backend's bytes."""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

from common import keys
from common.clock import NS, WallClock
from common.field_geojson import load_frame
from common.messages.sim import SimAntennas
from common.service import Context
from common.transport import Bus
from services.gnss.config import AntennaConfig, GnssConfig
from services.gnss.receiver import SimReceiver
from services.gnss.sim.config import ReachFaults, ReachOutput, ReachSimConfig
from services.gnss.sim.reach import ReachSim


class FakeBus:
    def __init__(self) -> None:
        self.on_truth: Callable[[SimAntennas], None] | None = None

    def subscribe(self, topic: Any, callback: Callable[[SimAntennas], None]) -> None:
        assert topic is keys.SIM_ANTENNAS
        self.on_truth = callback

    def report(self, name: str, read: Callable[[], int]) -> None:
        pass


def truth(k: int) -> SimAntennas:
    """10 Hz truth of a robot driving at 0.5 m/s, with every fault the simulator has."""
    x = 0.05 * k
    return SimAntennas(
        stamp_ns=k * NS // 10,
        p1=(x, 2.0, 1.1),
        p2=(x + 0.95, 2.0, 1.1),
        outage1=20 <= k < 25,
        force_float1=30 <= k < 40,
        offset1=(0.3, -0.2) if 45 <= k < 50 else (0.0, 0.0),
    )


def recv_exactly(sock: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = sock.recv(n - len(out))
        assert chunk, "closed early"
        out += chunk
    return out


def test_tcp_bytes_equal_the_sim_backend_through_every_fault(tmp_path: Path) -> None:
    bus = FakeBus()
    ctx = Context(
        "reach-sim", "test", cast(Bus, bus), WallClock(), logging.getLogger("t"), tmp_path, "engr"
    )
    cfg = ReachSimConfig(
        outputs=[ReachOutput(id=1, tcp_port=0)], faults=ReachFaults(drop_links_at_s=[9.0])
    )
    sim = ReachSim(ctx, cfg)
    backend = SimReceiver(
        GnssConfig(backend="sim"), AntennaConfig(id=1), cast(Bus, FakeBus()), load_frame("engr")
    )
    stop = threading.Event()
    runner = threading.Thread(target=sim.run, args=(stop,))
    runner.start()
    try:
        with socket.create_connection(("127.0.0.1", sim.servers[1].port), timeout=5) as sock:
            # an epoch sent before the server took the client would go to nobody
            assert sim.servers[1].wait_accepted(1, timeout=5)
            assert bus.on_truth is not None
            for k in range(60):
                want = backend.epoch(truth(k)).encode()
                bus.on_truth(truth(k))
                if want:
                    assert recv_exactly(sock, len(want)) == want, k
            bus.on_truth(truth(90))  # the link drops before this epoch
            assert sock.recv(100) == b""
    finally:
        stop.set()
        runner.join()
