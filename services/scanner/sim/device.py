"""The scanner service's ``sim`` backend: the emulated FARO on a virtual bus private
to the process, its completed scans rendered by the simulator onto its card."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

import can

from common import clock as clk
from common.clock import Clock
from common.service import Context
from services.scanner.config import ScannerConfig
from services.scanner.sim.card import RenderedCard, emulate

# the emulated scan advances this often (sim time): twice its status period of 0.1 s
TICK_HZ = 20.0


class BusOffGate(can.BusABC):
    """The client's end of a bus whose scanner node may go bus-off (the emulator's
    ``bus_off`` fault): while ``off()`` holds, :meth:`send` raises
    ``can.CanOperationError`` (as python-can's socketcan does when a frame finds no
    node to acknowledge it and the transmit queue fills: ENOBUFS) and ``state`` is
    ``BusState.ERROR``; otherwise it passes through to ``inner``, which it owns."""

    def __init__(self, inner: can.BusABC, off: Callable[[], bool]) -> None:
        super().__init__(channel=inner.channel_info)
        self.channel_info = f"{inner.channel_info} (bus-off fault gate)"
        self._inner, self._off = inner, off

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self._off():
            raise can.CanOperationError("Failed to transmit: bus-off (simulated fault)")
        self._inner.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        return self._inner.recv(timeout), False

    @property
    def state(self) -> can.BusState:
        return can.BusState.ERROR if self._off() else self._inner.state

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        self._inner.state = new_state

    def shutdown(self) -> None:
        super().shutdown()
        self._inner.shutdown()


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
