"""The world's pace set while it runs (``rpc/sim/run`` with a real-time factor)."""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any, cast

from common import keys
from common.clock import NS, WallClock
from common.messages.sim import SimClock, SimRun
from common.service import Context
from common.transport import Bus
from services.sim.config import SimConfig
from services.sim.service import SimService
from tests.sim.test_faults import TINY, _FakeBus


class _ServingBus(_FakeBus):
    def __init__(self) -> None:
        super().__init__()
        self.handlers: dict[str, Any] = {}

    def serve(self, rpc: Any, handler: Any) -> None:
        self.handlers[rpc.key] = handler


def test_the_world_takes_a_new_real_time_factor_while_it_runs(tmp_path: Path) -> None:
    bus = _ServingBus()
    ctx = Context(
        "sim", "test", cast(Bus, bus), WallClock(), logging.getLogger("sim"), tmp_path, TINY
    )
    svc = SimService(ctx, SimConfig(real_time_factor=1000.0, resume=False, snapshot_s=0.0))
    run = bus.handlers[keys.SIM_RUN.key]
    stop = threading.Event()
    ticks: list[SimClock] = []

    class _Clock:
        def put(self, msg: SimClock) -> None:
            ticks.append(msg)
            if msg.sim_ns >= 1 * NS and msg.real_time_factor == 1000.0:
                run(SimRun(real_time_factor=200.0))  # as phenorover sim does, from outside
            if msg.sim_ns >= 2 * NS:
                stop.set()

    svc.clock_pub = _Clock()  # type: ignore[assignment]
    svc.run(stop)
    rates = [t.real_time_factor for t in ticks]
    first = rates.index(200.0)
    assert ticks[first].sim_ns >= 1 * NS and set(rates[:first]) == {1000.0}
    assert set(rates[first:]) == {200.0}
    # a run without a factor keeps the pace it has
    assert run(SimRun()).real_time_factor == 200.0 and svc.real_time_factor == 200.0
