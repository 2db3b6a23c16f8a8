"""The simulated FARO behind a serial CAN adapter, as its own process.

``python -m services.scanner.sim.faro --manifest M`` (``[services.faro-sim]``, see
:class:`~services.scanner.sim.config.FaroSimConfig`) runs the FARO emulator on the
adapter's end of an SLCAN link over a pseudo-terminal, and links ``link`` to the
terminal. The scanner service then drives it with its hardware backend, unchanged:
``backend = "can"``, ``interface = "slcan"``, ``channel = <link>``, through
python-can as it drives a CANable on a serial port. Faults are the emulator's
(:class:`~services.scanner.sim.emulator.FaroFaults`); bus-off shows on the wire as an
adapter reports it (see :mod:`services.scanner.sim.slcan_device`). Completed scans are
rendered by the simulator (``rpc/sim/render``) into ``storage_dir``, as with the
``sim`` backend, in the folder of the mission under way (``mission/state``): the
scanner service reports ``<storage_dir>/<project>/Scan_NNNNN.e57`` for the project
it was given, which the CAN interface does not carry, so the emulator plays the
operator who set the scanner's project to the mission's name.
"""

from __future__ import annotations

import threading
from pathlib import Path

from common import keys
from common.messages.mission import MissionState
from common.service import Context, run
from services.scanner.sim.card import RenderedCard, emulate
from services.scanner.sim.config import FaroSimConfig
from services.scanner.sim.slcan_device import SlcanDevice


class FaroSim:
    def __init__(self, ctx: Context, cfg: FaroSimConfig) -> None:
        self.ctx = ctx
        self.card = RenderedCard(ctx, cfg.storage_dir, cfg.render_step_deg)
        self.device = SlcanDevice.open_pty(Path(cfg.link))
        self.emulator = emulate(ctx, self.device, self.card, cfg.faults, cfg.scan_time_s)
        self.device.bus_off = self.emulator.bus_off
        dev = self.device
        ctx.bus.report("slcan_bad_lines", lambda: dev.bad_lines)
        ctx.bus.report("slcan_dropped", lambda: dev.dropped)
        ctx.log.info("FARO on SLCAN at %s -> %s", cfg.link, dev.tty_path)
        ctx.bus.subscribe(keys.MISSION_STATE, self._on_mission)

    def _on_mission(self, state: MissionState) -> None:
        name = state.mission
        if name != self.card.project and Path(name).name == name and name not in (".", ".."):
            self.card.project = name  # a plain folder name only: never out of the card

    def run(self, stop: threading.Event) -> None:
        self.emulator.start()
        try:
            stop.wait()
        finally:
            self.emulator.stop()
            self.device.shutdown()


def build(ctx: Context, cfg: FaroSimConfig) -> FaroSim:
    return FaroSim(ctx, cfg)


if __name__ == "__main__":
    run("faro-sim", FaroSimConfig, build)
