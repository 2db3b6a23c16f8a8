"""The CAN side of the scanner: a real bus, or a bus with the FARO emulator on it.

``BACKENDS`` maps the config's ``backend`` to a factory returning the bus the client
drives; the sim backend also runs the emulator, whose completed scans the simulator
renders (``rpc/sim/render``) into the storage folder, as a real scan lands on the
scanner's card.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path

import can

from common import keys
from common.messages.sim import RenderRequest
from common.service import Context
from services.scanner.can_codec import ScanProfile
from services.scanner.config import ScannerConfig
from services.scanner.emulator import FaroEmulator, default_scan_duration_s


def scan_path(storage_dir: str, scan_id: int, project: str = "") -> Path:
    """Where scan ``scan_id`` of ``project`` is stored (FARO's naming: Scan_00001)."""
    return Path(storage_dir) / project / f"Scan_{scan_id:05d}.e57"


class CanDevice:
    project = ""  # the scan project the next scans go to (set by the service)

    def __init__(self, ctx: Context, cfg: ScannerConfig) -> None:
        self.bus: can.BusABC = can.Bus(
            interface=cfg.interface, channel=cfg.channel, bitrate=cfg.bitrate
        )

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

    project = ""  # the scan project the next scans go to (set by the service)

    def __init__(self, ctx: Context, cfg: ScannerConfig) -> None:
        channel = f"faro-sim-{os.getpid()}"
        client_bus = can.Bus(interface="virtual", channel=channel)
        self._device_bus = can.Bus(interface="virtual", channel=channel)
        self._ctx, self._cfg = ctx, cfg
        self._inclination = (0.0, 0.0)
        Path(cfg.storage_dir).mkdir(parents=True, exist_ok=True)
        fixed = cfg.sim_scan_time_s

        def duration(p: ScanProfile) -> float:
            return default_scan_duration_s(p) if fixed is None else fixed

        self.emulator = FaroEmulator(
            self._device_bus,
            now=lambda: ctx.clock.now_ns() / 1e9,
            scan_duration_s=duration,
            faults=cfg.sim_faults,
            on_scan_complete=self._store,
            inclination_deg=lambda: self._inclination,
        )
        self.bus: can.BusABC = BusOffGate(client_bus, self.emulator.bus_off)
        self.emulator.start()

    def _store(self, scan_id: int, profile: ScanProfile) -> None:
        path = scan_path(self._cfg.storage_dir, scan_id, self.project)
        path.parent.mkdir(parents=True, exist_ok=True)
        req = RenderRequest(
            scan_id=scan_id, path=str(path.resolve()), step_deg=self._cfg.render_step_deg
        )
        rep = self._ctx.bus.call(keys.SIM_RENDER, req, timeout=300.0)
        self._inclination = (math.degrees(rep.pitch), math.degrees(rep.roll))
        self._ctx.log.info(
            "scan %d stored: %s (%d points, rendered in %.1f s)",
            scan_id,
            rep.path,
            rep.points,
            rep.render_s,
        )

    def close(self) -> None:
        self.emulator.stop()
        self._device_bus.shutdown()
        self.bus.shutdown()


BACKENDS: dict[str, type[CanDevice] | type[SimDevice]] = {"can": CanDevice, "sim": SimDevice}
