"""The CAN side of the scanner: a real bus, or (``backend = "sim"``) a bus with the
FARO emulator on it (:mod:`services.scanner.sim.device`), whose completed scans the
simulator renders (``rpc/sim/render``) into the storage folder, as a real scan lands
on the scanner's card. :func:`open_device` opens the one the config names.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Protocol

import can

from common.config import ConfigError
from common.service import Context
from services.scanner.config import ScannerConfig
from services.scanner.slcan_host import SlcanHost

__all__ = ["CanDevice", "Device", "open_device", "scan_path"]

log = logging.getLogger(__name__)


class CanDevice:
    """A real bus: SocketCAN, or an SLCAN serial adapter (``interface = "slcan"``,
    through :class:`SlcanHost`, which also reads the adapter's error flags)."""

    project = ""  # the scan project the next scans go to (set by the service)

    def __init__(self, ctx: Context, cfg: ScannerConfig) -> None:
        self.name = f"{cfg.interface} channel {cfg.channel!r}"
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
        """Shut the bus; an adapter already gone (unplugged, its pty closed) is said in
        one line, not a traceback that ends the service's stop."""
        try:
            self.bus.shutdown()
        except (can.CanError, OSError) as exc:
            log.warning("scanner: CAN %s did not close cleanly: %s", self.name, exc)


class Device(Protocol):
    """What the service drives: the bus its client talks on, the scan project, why
    the bus is in error ("" when it is not), and closing it."""

    bus: can.BusABC
    project: str

    def bus_error(self) -> str: ...

    def close(self) -> None: ...


def open_device(ctx: Context, cfg: ScannerConfig) -> Device:
    """The device of ``cfg.backend``: a real bus, or the emulated FARO (its module,
    :mod:`services.scanner.sim`, loaded only then)."""
    if cfg.backend == "sim":
        from services.scanner.sim.device import SimDevice

        return SimDevice(ctx, cfg)
    return CanDevice(ctx, cfg)


def scan_path(storage_dir: str, scan_id: int, project: str = "") -> Path:
    """Where scan ``scan_id`` of ``project`` is stored (FARO's naming: Scan_00001)."""
    return Path(storage_dir) / project / f"Scan_{scan_id:05d}.e57"
