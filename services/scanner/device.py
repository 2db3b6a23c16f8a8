"""The CAN side of the scanner: a real bus, or a bus with the FARO emulator on it.

``BACKENDS`` maps the config's ``backend`` to a factory returning the bus the client
drives; the sim backend also runs the emulator, whose completed scans the simulator
renders (``rpc/sim/render``) into the storage folder, as a real scan lands on the
scanner's card.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

import can

from common import clock as clk
from common.clock import Clock
from common.config import ConfigError
from common.service import Context
from services.scanner.card import RenderedCard, emulate, scan_path
from services.scanner.config import ScannerConfig
from services.scanner.slcan_host import SlcanHost

__all__ = ["BACKENDS", "BusOffGate", "CanDevice", "SimDevice", "scan_path"]

# the emulated scan advances this often (sim time): twice its status period of 0.1 s
TICK_HZ = 20.0


class CanDevice:
    """A real bus: SocketCAN, or an SLCAN serial adapter (``interface = "slcan"``,
    through :class:`SlcanHost`, which also reads the adapter's error flags)."""

    project = ""  # the scan project the next scans go to (set by the service)

    def __init__(self, ctx: Context, cfg: ScannerConfig) -> None:
        try:
            if cfg.interface == "slcan":
                self.bus: can.BusABC = SlcanHost(
                    cfg.channel, bitrate=cfg.bitrate, tty_baudrate=cfg.tty_baudrate
                )
            else:
                self.bus = can.Bus(
                    interface=cfg.interface, channel=cfg.channel, bitrate=cfg.bitrate
                )
        except (can.CanError, OSError, ValueError) as exc:
            # one line naming what could not be opened, not a traceback
            raise ConfigError(
                f"scanner: cannot open CAN {cfg.interface} channel {cfg.channel!r}: {exc}"
            ) from None

    def bus_error(self) -> str:
        """What is wrong with the bus in one line; empty while it is fine."""
        if isinstance(self.bus, SlcanHost):
            return self.bus.error()
        state = self.bus.state
        return "" if state == can.BusState.ACTIVE else f"bus state {state.name}"

    def close(self) -> None:
        self.bus.shutdown()


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


BACKENDS: dict[str, type[CanDevice] | type[SimDevice]] = {"can": CanDevice, "sim": SimDevice}
