"""The scanner service's ``sim`` backend: the emulated FARO on a virtual bus private
to the process, its completed scans rendered by the simulator onto its card."""

from __future__ import annotations

import os
import threading

import can

from common import clock as clk
from common.clock import Clock
from common.service import Context
from services.scanner.config import ScannerConfig
from services.scanner.device import TICK_HZ, BusOffGate
from services.scanner.sim.card import RenderedCard, emulate


class SimDevice:
    """The emulated FARO on a virtual bus private to this process."""

    def __init__(self, ctx: Context, cfg: ScannerConfig) -> None:
        channel = f"faro-sim-{os.getpid()}"
        client_bus = can.Bus(interface="virtual", channel=channel)
        self._device_bus = can.Bus(interface="virtual", channel=channel)
        self.card = RenderedCard(ctx, cfg.storage_dir, cfg.render_step_deg)
        # the scan advances on the service's clock, in a thread of its own that the
        # clock lets run each step (in lockstep, at a fixed point of it); the
        # emulator's thread only answers frames
        self.emulator = emulate(
            ctx, self._device_bus, self.card, cfg.sim_faults, cfg.sim_scan_time_s, timed=False
        )
        self.bus: can.BusABC = BusOffGate(client_bus, self.emulator.bus_off)
        self.emulator.start()
        self._stop = threading.Event()
        self._ticker = threading.Thread(
            target=self._tick, args=(ctx.clock,), name="faro-scan", daemon=True
        )
        self._ticker.start()

    def _tick(self, clock: Clock) -> None:
        for _ in clk.ticks(clock, TICK_HZ, self._stop):
            self.emulator.tick()

    @property
    def project(self) -> str:
        return self.card.project

    @project.setter
    def project(self, project: str) -> None:
        self.card.project = project

    def bus_error(self) -> str:
        return "bus-off (simulated fault)" if self.emulator.bus_off() else ""

    def close(self) -> None:
        self._stop.set()
        self._ticker.join(timeout=2.0)
        self.emulator.stop()
        self._device_bus.shutdown()
        self.bus.shutdown()
